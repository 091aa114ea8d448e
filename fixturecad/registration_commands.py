"""CLI: ``fixturecad register | simulate``: thin wrappers over a fixture's generated register.py."""

import json
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from fixturecad.errors import InputError

app = typer.Typer()

# A simulated trial succeeds when the routine says "unique" and the pose is within
# this floor plus SUCCESS_BOUND_FACTOR times the Cramer-Rao standard deviation.
SUCCESS_TRANSLATION_MM = 0.1
SUCCESS_ROTATION_DEG = 0.1
SUCCESS_BOUND_FACTOR = 6.0
DEFAULT_CHORD_TOLERANCE_MM = 0.01  # STL chord tolerance when features.json does not give it
PLOT_NAME = "simulation.png"
SUMMARY_NAME = "simulation.json"


class Positions(str, Enum):
    default = "default"
    random = "random"


def load_routine(out_dir: Path):
    """The generated register.py of a fixture folder, imported from its path."""
    import importlib.util

    path = Path(out_dir) / "register.py"
    if not path.is_file():
        raise InputError(f"no register.py in {out_dir}: run fixturecad build first")
    name = f"_fixturecad_generated_{abs(hash(str(path.resolve())))}"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _read_json(path: Path, what: str) -> dict:
    if not path.is_file():
        raise InputError(f"no {path.name} in {path.parent}: run fixturecad build first")
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise InputError(f"{what} {path} is not valid JSON: {error.msg}") from None


@app.command()
def register(
    out_dir: Annotated[Path, typer.Argument(help="Fixture folder written by fixturecad build.")],
    touches: Annotated[Path, typer.Argument(help="Touch file: CSV feature,x,y,z (mm, measurement frame) or JSON.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print the result as JSON.")] = False,
    sigma: Annotated[float, typer.Option(help="Sensor placement noise standard deviation, mm (each axis).")] = 0.005,
    lever: Annotated[float | None, typer.Option(help="Sensor size, mm: plane and line sensors tilt by sigma/lever rad (default: the engine's SENSOR_LEVER_MM).")] = None,
    ball_radius: Annotated[float | None, typer.Option(help="Ball tip radius, mm (touches are ball centres).")] = None,
):
    """Pose of the fixture (fixture2meas) from touches, by the fixture's generated register.py."""
    from fixturecad.registration.touchfile import check_enough, format_result, read_touch_file

    if not Path(out_dir).is_dir():
        raise InputError(f"fixture folder {out_dir} does not exist")
    if not (sigma > 0 and sigma < float("inf")):
        raise InputError(f"--sigma must be a positive number of mm, got {sigma}")
    lever = _lever(lever)
    routine = load_routine(out_dir)
    try:
        points, contacts, radius, approaches = read_touch_file(touches, list(routine.FEATURES))
        radius = radius if ball_radius is None else ball_radius
        check_enough(routine.FEATURES, points, contacts, radius)
        result = routine.register(points, sigma_mm=sigma, ball_radius_mm=radius, contacts=contacts,
                                  approaches=approaches, lever_mm=lever)
    except ValueError as error:
        raise InputError(str(error).splitlines()[0]) from None
    typer.echo(json.dumps(result, indent=2) if as_json else format_result(result))


@app.command()
def simulate(
    out_dir: Annotated[Path, typer.Argument(help="Fixture folder written by fixturecad build.")],
    trials: Annotated[int, typer.Option(help="Number of simulated registrations.")] = 1000,
    noise: Annotated[float, typer.Option(help="Sensor placement noise standard deviation, mm (each axis).")] = 0.005,
    lever: Annotated[float | None, typer.Option(help="Sensor size, mm: plane and line sensors tilt by noise/lever rad (default: the engine's SENSOR_LEVER_MM).")] = None,
    plan: Annotated[Positions, typer.Option(help="Touch positions: the plan's nominal points or random ones on the same features.")] = Positions.default,
    touch_plan: Annotated[str, typer.Option(help="Named touch plan of features.json.")] = "default",
    seed: Annotated[int, typer.Option(help="Seed of the random generator.")] = 0,
    nominal: Annotated[bool, typer.Option(help="Give the routine a nominal pose (1 deg, 1 mm off the truth).")] = False,
):
    """Register synthetic noisy touches sampled on the STL; compare the errors with the Cramer-Rao bound."""
    import numpy as np

    from fixturecad.registration.sampling import TouchSampler, load_mesh

    if trials < 1:
        raise InputError(f"--trials must be at least 1, got {trials}")
    if not (noise >= 0 and noise < float("inf")):
        raise InputError(f"--noise must be a non-negative number of mm, got {noise}")
    lever = _lever(lever)
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        raise InputError(f"fixture folder {out_dir} does not exist")
    document = _read_json(out_dir / "features.json", "features file")
    stl = out_dir / "fixture.stl"
    if not stl.is_file():
        raise InputError(f"no fixture.stl in {out_dir}: run fixturecad build first")
    routine = load_routine(out_dir)
    try:
        sampler = TouchSampler(document, load_mesh(stl), touch_plan, plan is Positions.random)
    except ValueError as error:
        raise InputError(str(error).splitlines()[0]) from None
    rng = np.random.default_rng(seed)
    # The residual test allows for the tessellation: chord errors spread over [0, tolerance].
    chord = float((document.get("files") or {}).get("stl_tolerance_mm", DEFAULT_CHORD_TOLERANCE_MM))
    sigma = float(np.sqrt(noise**2 + chord**2 / 3.0))
    records = []
    with typer.progressbar(range(trials), label="simulating", file=_progress_stream()) as bar:
        for _ in bar:
            records.append(_trial(routine, sampler, rng, noise, sigma, nominal, lever))
    summary = summarise(records, noise)
    summary.update({"trials": trials, "noise_mm": noise, "lever_mm": lever, "plan": plan.value, "touch_plan": touch_plan, "seed": seed,
                    "nominal_pose": nominal})
    (out_dir / SUMMARY_NAME).write_text(json.dumps(summary, indent=2))
    plot_errors(records, summary, out_dir / PLOT_NAME)
    typer.echo(format_summary(summary))
    typer.echo(f"plot: {out_dir / PLOT_NAME}")


def _lever(lever):
    """The sensor lever (mm) of --lever, the engine's default when not given."""
    if lever is None:
        from fixturecad.registration.engine import SENSOR_LEVER_MM

        return SENSOR_LEVER_MM
    if not (lever > 0 and lever < float("inf")):
        raise InputError(f"--lever must be a positive number of mm, got {lever}")
    return lever


def _progress_stream():
    import io
    import sys

    return sys.stderr if sys.stderr.isatty() else io.StringIO()


def _trial(routine, sampler, rng, noise, sigma, nominal, lever):
    """One registration of fresh synthetic touches: errors, status and the Cramer-Rao bound."""
    import time

    import numpy as np

    from fixturecad.registration.engine import Problem, build_groups, cramer_rao_bound, sigmas
    from fixturecad.registration.pose import apply_twist, fixture2meas_from_rt, pose_errors

    touches, contacts, truth = sampler.draw(rng, noise, lever_mm=lever)
    initial = None
    if nominal:
        twist = np.concatenate([np.radians(1.0) * _unit(rng), 1.0 * _unit(rng)])
        initial = fixture2meas_from_rt(*apply_twist(truth[:3, :3], truth[:3, 3], twist))
    start = time.perf_counter()
    result = routine.register(touches, initial_pose=initial, sigma_mm=sigma, contacts=contacts, lever_mm=lever)
    elapsed = time.perf_counter() - start
    err_t, err_r = pose_errors(np.array(result["pose"]), truth)
    problem = Problem(build_groups(sampler.features, touches, 0.0, contacts), sigma, lever)
    bound_t, bound_r = sigmas(cramer_rao_bound(problem, truth, noise if noise > 0 else sigma))
    return {
        "status": result["status"],
        "translation_error_mm": err_t,
        "rotation_error_deg": float(np.degrees(err_r)),
        "crb_translation_mm": bound_t,
        "crb_rotation_deg": bound_r,
        "time_s": elapsed,
    }


def _unit(rng):
    import numpy as np

    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def summarise(records, noise):
    """Median, 95th percentile and RMS of the errors, success rate, ratio of RMS error to the bound."""
    import numpy as np

    et = np.array([r["translation_error_mm"] for r in records])
    er = np.array([r["rotation_error_deg"] for r in records])
    bt = np.array([r["crb_translation_mm"] if r["crb_translation_mm"] is not None else np.nan for r in records])
    br = np.array([r["crb_rotation_deg"] if r["crb_rotation_deg"] is not None else np.nan for r in records])
    success = np.array([
        r["status"] == "unique"
        and a <= SUCCESS_TRANSLATION_MM + SUCCESS_BOUND_FACTOR * np.nan_to_num(c)
        and b <= SUCCESS_ROTATION_DEG + SUCCESS_BOUND_FACTOR * np.nan_to_num(d)
        for r, a, b, c, d in zip(records, et, er, bt, br)
    ])
    statuses = {}
    for r in records:
        statuses[r["status"]] = statuses.get(r["status"], 0) + 1
    rms_t, rms_r = float(np.sqrt(np.mean(et**2))), float(np.sqrt(np.mean(er**2)))
    crb_t, crb_r = float(np.sqrt(np.nanmean(bt**2))), float(np.sqrt(np.nanmean(br**2)))
    return {
        "median_translation_error_mm": float(np.median(et)),
        "p95_translation_error_mm": float(np.percentile(et, 95)),
        "median_rotation_error_deg": float(np.median(er)),
        "p95_rotation_error_deg": float(np.percentile(er, 95)),
        "rms_translation_error_mm": rms_t,
        "rms_rotation_error_deg": rms_r,
        "crb_translation_mm": crb_t,
        "crb_rotation_deg": crb_r,
        "ratio_translation_to_crb": rms_t / crb_t if noise > 0 else None,
        "ratio_rotation_to_crb": rms_r / crb_r if noise > 0 else None,
        "success_rate": float(success.mean()),
        "statuses": statuses,
        "median_time_ms": float(np.median([r["time_s"] for r in records]) * 1e3),
    }


def format_summary(s) -> str:
    ratio = (
        f"RMS error / Cramer-Rao bound: translation {s['ratio_translation_to_crb']:.3f}, rotation {s['ratio_rotation_to_crb']:.3f}"
        if s["ratio_translation_to_crb"] is not None else "noise 0: no Cramer-Rao ratio"
    )
    return "\n".join([
        f"trials: {s['trials']}  noise: {s['noise_mm']} mm  plan: {s['plan']} ({s['touch_plan']})",
        f"translation error: median {s['median_translation_error_mm'] * 1e3:.2f} um, "
        f"95th percentile {s['p95_translation_error_mm'] * 1e3:.2f} um "
        f"(bound {s['crb_translation_mm'] * 1e3:.2f} um RMS)",
        f"rotation error: median {s['median_rotation_error_deg'] * 1e3:.3f} mdeg, "
        f"95th percentile {s['p95_rotation_error_deg'] * 1e3:.3f} mdeg "
        f"(bound {s['crb_rotation_deg'] * 1e3:.3f} mdeg RMS)",
        ratio,
        f"success: {100 * s['success_rate']:.1f} %  statuses: "
        + ", ".join(f"{k} {v}" for k, v in sorted(s["statuses"].items())),
        f"median registration time: {s['median_time_ms']:.2f} ms",
    ])


def plot_errors(records, summary, path: Path) -> None:
    """Histograms of the translation and rotation errors with the RMS bound marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    panels = [
        ("translation_error_mm", 1e3, "translation error (um)", "crb_translation_mm", "rms_translation_error_mm"),
        ("rotation_error_deg", 1e3, "rotation error (mdeg)", "crb_rotation_deg", "rms_rotation_error_deg"),
    ]
    for ax, (key, scale, label, bound, rms) in zip(axes, panels):
        values = np.array([r[key] for r in records]) * scale
        ax.hist(values, bins=40, color="0.7")
        ax.axvline(summary[bound] * scale, color="tab:red", label="Cramer-Rao bound (RMS)")
        ax.axvline(summary[rms] * scale, color="tab:blue", linestyle="--", label="observed RMS")
        ax.set_xlabel(label)
        ax.set_ylabel("trials")
        ax.legend()
    fig.suptitle(f"{summary['trials']} trials, noise {summary['noise_mm']} mm, success {100 * summary['success_rate']:.1f} %")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
