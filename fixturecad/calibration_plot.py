"""calibration.png: how far each feature of the printed part departs from its drawing (matplotlib, Agg)."""

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure


def plot_calibration(document: dict, zone_mm: float, path: Path) -> None:
    """Each feature's largest departure from the drawing against the tolerance zone, a bar each."""
    calibration = document["calibration"]
    datums = {entry["feature"]: entry["role"] for entry in document["datums"]["features"]}
    names = list(calibration["features"])
    entries = [calibration["features"][n] for n in names]
    departure = np.array([e["departure_mm"] for e in entries]) * 1e3
    fig = Figure(figsize=(7.5, 4.0), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    x = np.arange(len(names))
    ax.bar(x, departure, color=["#2ca02c" if e["within_tolerance"] else "#d62728" for e in entries])
    ax.axhline(zone_mm / 2 * 1e3, color="#444444", linestyle="--")
    ax.text(-0.45, zone_mm / 2 * 1e3, f"tolerance +-{zone_mm / 2 * 1e3:g} um", ha="left", va="bottom",
            color="#444444")
    for k, (name, e) in enumerate(zip(names, entries)):
        note = f"{departure[k]:.0f} um" + (f"\n{datums[name]} datum" if name in datums else "")
        ax.text(k, departure[k], note, ha="center", va="bottom", fontsize=8)
    labels = [f"{n}\n{e['points']} points, rms {e['rms_residual_mm'] * 1e3:.1f} um" for n, e in zip(names, entries)]
    ax.set_xticks(x, labels, fontsize=8)
    ax.set_ylabel("largest departure from the drawing, um")
    ax.set_ylim(0, 1.3 * max(departure.max(), zone_mm / 2 * 1e3))
    ax.set_title(f"as-built calibration from {Path(calibration['source']).name} (red: outside the tolerance)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
