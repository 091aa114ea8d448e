"""CLI: ``fixturecad calibrate``: the as-built fixture from points measured on the printed part."""

import shutil
from datetime import datetime, timezone
from pathlib import Path
from typing import Annotated

import typer

from fixturecad import features_json
from fixturecad.errors import InputError
from fixturecad.registration.defaults import DEFAULT_SIGMA_MM
from fixturecad.registration_commands import Units
from fixturecad.staging import check_target, staged_folder

app = typer.Typer()

REPORT_NAME = "calibration.png"
COPIED = ("fixture.step", "fixture.stl", "preview.png")  # the drawing's files, kept beside the as-built model


@app.command()
def calibrate(
    out_dir: Annotated[Path, typer.Argument(help="Fixture folder written by fixturecad build.")],
    measurements: Annotated[Path, typer.Argument(help="CSV feature,x,y,z: points measured on the printed part, mm, any frame.")],
    out: Annotated[Path | None, typer.Option(help="As-built folder to write (default: OUT_DIR-asbuilt).")] = None,
    sigma: Annotated[float, typer.Option(help="Measurement noise standard deviation, mm (each axis).")] = DEFAULT_SIGMA_MM,
    force: Annotated[bool, typer.Option(help="Replace an as-built folder fixturecad wrote earlier.")] = False,
    units: Annotated[Units | None, typer.Option(help="The measurement file's lengths: mm, m or in (converted to mm); without it mm, and a file that looks like another unit is refused.")] = None,
):
    """Fit the printed part's features to measured points; write an as-built fixture folder."""
    from fixturecad.sideprocess import SideProcess

    side = SideProcess("calibration", "register")  # ready on the second core while we fit
    try:
        _calibrate(Path(out_dir), Path(measurements), out, sigma, force, side, units and units.value)
    except BaseException:
        side.cancel()
        raise


def _calibrate(out_dir: Path, measurements: Path, out, sigma: float, force: bool, side, units: str | None) -> None:
    import numpy as np

    from fixturecad.registration.calibration import calibrate as fit
    from fixturecad.registration.datums import DatumScheme
    from fixturecad.registration.features import features_from_json
    from fixturecad.registration.planning import stored_candidates
    from fixturecad.registration.touchfile import read_touch_csv
    from fixturecad.registration.units import check_noise, check_spread, from_units

    if not (sigma > 0 and np.isfinite(sigma)):
        raise InputError(f"--sigma must be a positive number of mm, got {sigma}")
    try:
        check_noise(sigma, "--sigma")
    except ValueError as error:
        raise InputError(str(error)) from None
    document = features_json.read(out_dir)
    if "calibration" in document:
        raise InputError(f"{out_dir} is already an as-built folder: calibrate the folder it was made from")
    target = check_target(Path(out) if out is not None else out_dir.with_name(out_dir.name + "-asbuilt"), force,
                          "as-built", (out_dir,))  # before the fit: a folder it may not write is said at once
    features = features_from_json(document)
    try:
        with open(measurements, encoding="utf-8-sig", newline="") as handle:  # read row by row: a bad row stops it
            points, _, lines = read_touch_csv(handle, list(features))
        points = {fid: from_units(value, units or "mm") for fid, value in points.items()}
        if units is None:  # units given: the user has said
            check_spread(np.concatenate(list(points.values())), list(points), stored_candidates(document),
                         document.get("volume_mm3"), "the measured points")
        scheme = DatumScheme.from_json(document["datums"])
        zone = float(document["tolerance"]["zone_mm"])
        result = fit(features, scheme, points, sigma, zone, lines)
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"cannot read measurement file {measurements}: {error}") from None
    except ValueError as error:
        raise InputError(f"{measurements}: {str(error).splitlines()[0]}") from None
    as_built = _as_built_document(document, result, measurements, zone)
    _write(out_dir, target, as_built, zone, force, side)
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


def _write(out_dir: Path, target: Path, document: dict, zone_mm: float, force: bool, side) -> None:
    """The as-built folder, written beside the target and moved into place when complete (the caller cancels
    the side process on failure)."""
    with staged_folder(target, force, "as-built", inputs=(out_dir,)) as staging:
        for name in COPIED:
            if (out_dir / name).is_file():
                shutil.copy2(out_dir / name, staging / name)
        features_json.write(document, staging / features_json.NAME)
        side.send(("calibration", document, zone_mm, staging / REPORT_NAME), ("register", document, staging / "register.py"))
        side.wait()
