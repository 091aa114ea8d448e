"""CLI: ``fixturecad calibrate``: the as-built fixture from points measured on the printed part."""

import shutil
from datetime import datetime, timezone
from pathlib import Path
from typing import Annotated

import typer

from fixturecad import features_json
from fixturecad.errors import InputError

app = typer.Typer()

REPORT_NAME = "calibration.png"
COPIED = ("fixture.step", "fixture.stl", "preview.png")  # the drawing's files, kept beside the as-built model


@app.command()
def calibrate(
    out_dir: Annotated[Path, typer.Argument(help="Fixture folder written by fixturecad build.")],
    measurements: Annotated[Path, typer.Argument(help="CSV feature,x,y,z: points measured on the printed part, mm, any frame.")],
    out: Annotated[Path | None, typer.Option(help="As-built folder to write (default: OUT_DIR-asbuilt).")] = None,
    sigma: Annotated[float, typer.Option(help="Measurement noise standard deviation, mm (each axis).")] = 0.005,
    force: Annotated[bool, typer.Option(help="Replace an as-built folder fixturecad wrote earlier.")] = False,
):
    """Fit the printed part's features to measured points; write an as-built fixture folder."""
    import numpy as np

    from fixturecad.registration.calibration import calibrate as fit
    from fixturecad.registration.datums import DatumScheme
    from fixturecad.registration.features import features_from_json
    from fixturecad.registration.touchfile import read_touch_csv

    out_dir = Path(out_dir)
    if not (sigma > 0 and np.isfinite(sigma)):
        raise InputError(f"--sigma must be a positive number of mm, got {sigma}")
    document = features_json.read(out_dir)
    if "calibration" in document:
        raise InputError(f"{out_dir} is already an as-built folder: calibrate the folder it was made from")
    target = Path(out) if out is not None else out_dir.with_name(out_dir.name + "-asbuilt")
    features = features_from_json(document)
    try:
        text = measurements.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"cannot read measurement file {measurements}: {error}") from None
    try:
        points, _, lines = read_touch_csv(text, list(features))
        scheme = DatumScheme.from_json(document["datums"])
        zone = float(document["tolerance"]["zone_mm"])
        result = fit(features, scheme, points, sigma, zone, lines)
    except ValueError as error:
        raise InputError(f"{measurements}: {str(error).splitlines()[0]}") from None
    as_built = _as_built_document(document, result, measurements, zone)
    _write(out_dir, target, as_built, result, zone, force)
    typer.echo(format_report(as_built["calibration"], zone))
    typer.echo(f"as-built fixture: {target}")


def _as_built_document(document, result, measurements: Path, zone_mm: float) -> dict:
    """features.json of the as-built part: its features, and where they came from."""
    features = {}
    for fid, entry in result.features.items():
        features[fid] = {**_feature_json(entry), "extent": next(
            e for e in document["features"] if e["id"] == fid).get("extent")}
    per_feature = {}
    for fid in result.features:
        per_feature[fid] = {
            "points": result.counts[fid],
            "rms_residual_mm": result.rms_mm[fid],
            "departure_mm": result.worst_mm[fid],
            "within_tolerance": result.worst_mm[fid] <= zone_mm / 2,
            "modes": list(result.mode_names[fid]),
            "deviation": result.deviations[fid].tolist(),
            "covariance": result.covariances[fid].tolist(),
        }
    calibration = {
        "drawing": document["features"],
        "source": str(measurements),
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "sigma_mm": result.sigma_mm,
        "features": per_feature,
    }
    out = dict(document)
    out["features"] = [{**entry, **{k: v for k, v in features[entry["id"]].items() if v is not None}}
                       for entry in document["features"]]
    out["calibration"] = calibration
    return out


def _feature_json(feature) -> dict:
    entry = feature.to_json()
    entry.pop("extent", None)
    return entry


def format_report(calibration: dict, zone_mm: float) -> str:
    """The calibration as a table: each feature, its points, fit and how far it departs from the drawing."""
    lines = [f"{'feature':12s} {'points':>6s} {'rms um':>8s} {'departure mm':>13s}  verdict"]
    for fid, entry in calibration["features"].items():
        verdict = "within tolerance" if entry["within_tolerance"] else f"OUT of the {zone_mm:g} mm zone"
        lines.append(f"{fid:12s} {entry['points']:6d} {entry['rms_residual_mm'] * 1e3:8.1f} "
                     f"{entry['departure_mm']:13.4f}  {verdict}")
    return "\n".join(lines)


def _write(out_dir: Path, target: Path, document: dict, result, zone_mm: float, force: bool) -> None:
    from fixturecad.registration.generate import write_register_script

    if target.exists() and not force:
        raise InputError(f"{target} already exists; pass --force to replace it")
    staging = target.with_name(f".{target.name}.calibrating")
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir(parents=True)
    try:
        for name in COPIED:
            if (out_dir / name).is_file():
                shutil.copy2(out_dir / name, staging / name)
        features_json.write(document, staging / features_json.NAME)
        write_register_script(document, staging / "register.py")
        plot_calibration(document, zone_mm, staging / REPORT_NAME)
        if target.exists():
            shutil.rmtree(target)
        staging.rename(target)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def plot_calibration(document: dict, zone_mm: float, path: Path) -> None:
    """Each feature's largest departure from the drawing against the tolerance zone, a bar each."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

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
