"""CLI: ``fixturecad register | simulate``: thin wrappers over a fixture's generated register.py."""

import json
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from fixturecad import features_json
from fixturecad.errors import InputError
from fixturecad.staging import check_files, staged_files
from fixturecad.registration.controllers import FORMATS
from fixturecad.registration.defaults import DEFAULT_SIGMA_MM, SENSOR_LEVER_MM
from fixturecad.registration.units import UNITS_MM, check_noise

app = typer.Typer()

# A simulated trial succeeds when the routine says "unique" and the pose is within
# this floor plus SUCCESS_BOUND_FACTOR times the Cramer-Rao standard deviation.
SUCCESS_TRANSLATION_MM = 0.1
SUCCESS_ROTATION_DEG = 0.1
SUCCESS_BOUND_FACTOR = 6.0
MAX_TRIALS = 100_000  # a day's run at the slowest fixtures' second a trial
ANNOUNCED_S = 60.0  # a run predicted longer than this says how long before it goes on
PARALLEL_S = 10.0  # the trials' time (s) a worker process is given at least: each sets itself up first
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
    try:
        spec.loader.exec_module(module)
    except Exception as error:  # whatever a damaged file raises, the user's remedy is the same
        raise InputError(f"{path} is damaged ({type(error).__name__}): rebuild the fixture") from None
    if not all(hasattr(module, name) for name in ("FEATURES", "register")):
        raise InputError(f"{path} is not a fixturecad registration routine: rebuild the fixture")
    return module


PoseFormat = Enum("PoseFormat", {name: name for name in FORMATS}, type=str)
Units = Enum("Units", {name: name for name in UNITS_MM}, type=str)


@app.command()
def register(
    out_dir: Annotated[Path, typer.Argument(help="Fixture folder written by fixturecad build.")],
    touches: Annotated[Path, typer.Argument(help="Touch file: CSV feature,x,y,z (mm, measurement frame) or JSON (docs/touch-files.md).")],
    as_json: Annotated[bool, typer.Option("--json", help="Print the result as JSON.")] = False,
    pose_format: Annotated[PoseFormat, typer.Option("--format", help="The pose in a robot controller's convention and units (docs/robot-frames.md).")] = PoseFormat.matrix,
    sigma: Annotated[float, typer.Option(help="Sensor placement noise standard deviation, mm (each axis).")] = DEFAULT_SIGMA_MM,
    lever: Annotated[float, typer.Option(help="Sensor size, mm: plane and line sensors tilt by sigma/lever rad.")] = SENSOR_LEVER_MM,
    ball_radius: Annotated[float | None, typer.Option(help="Ball tip radius, mm (touches are ball centres; default: as the touch file says, a CSV 0).")] = None,
    units: Annotated[Units | None, typer.Option(help="The touch file's lengths: mm, m or in (converted to mm); without it mm, and a file that looks like another unit is refused.")] = None,
    fixture_tolerance: Annotated[float | None, typer.Option(help="Profile tolerance zone width of the printed features, mm (default: as recorded in features.json; 0: an exact part).")] = None,
    target_sigma: Annotated[float | None, typer.Option(help="Accuracy wanted: RMS translation standard deviation, mm.")] = None,
    target_sigma_deg: Annotated[float | None, typer.Option(help="Accuracy wanted: RMS rotation standard deviation, deg.")] = None,
    unlabelled: Annotated[bool, typer.Option(help="Take every point touch as unlabelled: on some plane, sphere or cylinder, not said which (an empty feature in a CSV, null in JSON, is unlabelled already).")] = False,
    anywhere: Annotated[bool, typer.Option(help="The unlabelled touches lie anywhere on the part (on any face of the solid), not only on its sensing features.")] = False,
):
    """Pose of the fixture's datum frame (fixture2meas) from touches, on the folder's features.json (the
    copy in its register.py is for register.py run alone).

    Exit code: 0 unique, 3 ambiguous, 4 underdetermined, 5 inconsistent, 6 search incomplete, 2 bad input.
    """
    from fixturecad.registration.deviations import tolerance_from_document
    from fixturecad.registration.engine import register_touches
    from fixturecad.registration.features import faces_from_json, features_from_json
    from fixturecad.registration.planning import stored_candidates
    from fixturecad.registration.touchfile import exit_code, register_file, repeated_warning, report, target

    if not Path(out_dir).is_dir():
        raise InputError(f"fixture folder {out_dir} does not exist")
    document = features_json.read(out_dir)  # one line for a missing, damaged or older features.json
    features, candidates = features_from_json(document), stored_candidates(document)

    def routine(touches, fixture_tolerance_mm=None, anywhere=False, **options):
        faces = faces_from_json(document) if anywhere else {}
        tolerance = tolerance_from_document({**features, **faces}, document, fixture_tolerance_mm)
        return register_touches(features, touches, tolerance=tolerance, candidates=candidates, faces=faces or None,
                                **options)

    try:
        result = register_file(features, routine, touches, sigma, lever, ball_radius, fixture_tolerance,
                               target(target_sigma, target_sigma_deg), units and units.value, (candidates, document.get("volume_mm3")),
                               unlabelled, anywhere)
    except ValueError as error:
        raise InputError(str(error).splitlines()[0]) from None
    if repeated_warning(result):
        typer.echo(f"fixturecad: {repeated_warning(result)}", err=True)
    typer.echo(report(result, pose_format.value, as_json))
    raise typer.Exit(exit_code(result))


@app.command()
def simulate(
    out_dir: Annotated[Path, typer.Argument(help="Fixture folder written by fixturecad build.")],
    trials: Annotated[int, typer.Option(help="Number of simulated registrations.")] = 1000,
    noise: Annotated[float, typer.Option(help="Sensor placement noise standard deviation, mm (each axis).")] = DEFAULT_SIGMA_MM,
    lever: Annotated[float, typer.Option(help="Sensor size, mm: plane and line sensors tilt by noise/lever rad.")] = SENSOR_LEVER_MM,
    plan: Annotated[Positions, typer.Option(help="Touch positions: the plan's nominal points or random ones on the same features.")] = Positions.default,
    touch_plan: Annotated[str, typer.Option(help="Named touch plan of features.json, or of plans/NAME.json written by fixturecad plan.")] = "default",
    seed: Annotated[int, typer.Option(min=0, help="Seed of the random generator (0 or more).")] = 0,
    nominal: Annotated[bool, typer.Option(help="Give the routine a nominal pose (1 deg, 1 mm off the truth).")] = False,
    fixture_tolerance: Annotated[float | None, typer.Option(help="Print the fixture within a profile tolerance zone this wide, mm (default: as recorded in features.json; 0: an exact part).")] = None,
    out: Annotated[Path | None, typer.Option(help=f"Folder for {SUMMARY_NAME} and {PLOT_NAME} [default: the fixture folder].")] = None,
    force: Annotated[bool, typer.Option(help=f"Replace {SUMMARY_NAME} and {PLOT_NAME} written earlier.")] = False,
    unlabelled: Annotated[bool, typer.Option(help="Register the point touches without their labels (the bound is that of the same touches labelled).")] = False,
    anywhere: Annotated[bool, typer.Option(help="Draw the point touches anywhere on the part a probe reaches, not on the plan's features, and register them unlabelled, on any face (the bound: the same touches labelled with their faces).")] = False,
    jobs: Annotated[int, typer.Option(min=0, help=f"Processes the trials run in (0: up to one a core, each with {PARALLEL_S:g} s of trials or more); the trials are the same whatever the number.")] = 0,
):
    """Register synthetic noisy touches sampled on the STL; compare the errors with the Cramer-Rao bound.

    With a fixture tolerance every trial touches a freshly printed part (its
    features spread evenly over the zone) and the errors are split: from the
    touch noise alone (a perfect part), from the part alone (no noise), in all.
    """
    import math
    import multiprocessing
    import os
    import time

    import numpy as np

    if not 1 <= trials <= MAX_TRIALS:
        raise InputError(f"--trials must be from 1 to {MAX_TRIALS:,}, got {trials}")
    if not (noise >= 0 and noise < float("inf")):
        raise InputError(f"--noise must be a non-negative number of mm, got {noise}")
    try:
        check_noise(noise, "--noise")
    except ValueError as error:
        raise InputError(str(error)) from None
    if not (lever > 0 and lever < float("inf")):
        raise InputError(f"--lever must be a positive number of mm, got {lever}")
    _check_tolerance(fixture_tolerance)
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        raise InputError(f"fixture folder {out_dir} does not exist")
    document = features_json.read(out_dir)
    stl = out_dir / "fixture.stl"
    if not stl.is_file():
        raise InputError(f"no fixture.stl in {out_dir}: run fixturecad build first")
    routine = load_routine(out_dir)
    if touch_plan not in document["plans"]:
        document = {**document, "plans": {**document["plans"], **_designed_plan(out_dir, touch_plan)}}
    unlabelled = unlabelled or anywhere
    sampling = (out_dir, document, touch_plan, plan is Positions.random, fixture_tolerance, anywhere)
    try:
        sampler = _sampler(*sampling)
    except ValueError as error:
        raise InputError(str(error).splitlines()[0]) from None
    tolerance = sampler.tolerance
    folder = check_files(out_dir if out is None else out, (SUMMARY_NAME, PLOT_NAME), force)
    # The residual test allows for the tessellation: chord errors spread over [0, tolerance].
    chord = float(document["files"]["stl_tolerance_mm"])
    options = (noise, float(np.sqrt(noise**2 + chord**2 / 3.0)), nominal, lever, fixture_tolerance, unlabelled)
    # Before it starts: a trial of its own touches (its own generator: the trials' touches stay those of the
    # seed), timed after one more that pays what only the first call does (imports, caches: the
    # quarter-sphere's first took two to four times the next). A whole trial: on a printed part its two
    # registrations from near the truth cost far less than the first.
    ahead = np.random.default_rng([seed, 1])
    _trial(routine, sampler, ahead, *options)
    start = time.perf_counter()
    _trial(routine, sampler, ahead, *options)
    one = time.perf_counter() - start
    workers = min(trials, jobs or os.cpu_count() or 1, jobs or math.ceil(one * trials / PARALLEL_S))
    predicted = one * trials / workers
    if predicted > ANNOUNCED_S:
        typer.echo(f"simulate: about {predicted / 60:.0f} min for {trials} trials ({one:.2f} s a trial"
                   f"{f', {workers} at a time' if workers > 1 else ''}); Ctrl-C stops it, writing nothing", err=True)
    records = []
    with typer.progressbar(length=trials, label="simulating", file=_progress_stream()) as bar:
        if workers == 1:
            for k in range(trials):
                records.append(_trial(routine, sampler, _trial_generator(seed, k), *options))
                bar.update(1)
        else:
            with multiprocessing.Pool(workers, _start_worker, (sampling, options, seed)) as pool:
                for record in pool.imap(_worker_trial, range(trials)):
                    records.append(record)
                    bar.update(1)
    summary = summarise(records, noise)
    summary.update({"trials": trials, "unlabelled": unlabelled, "anywhere": anywhere, "noise_mm": noise, "lever_mm": lever, "plan": plan.value, "touch_plan": touch_plan, "seed": seed,
                    "nominal_pose": nominal, "fixture_tolerance_mm": None if tolerance is None else tolerance.zone_mm,
                    "calibrated": tolerance is not None and "calibration" in document})
    with staged_files(folder, (SUMMARY_NAME, PLOT_NAME)) as staging:
        (staging / SUMMARY_NAME).write_text(json.dumps(summary, indent=2))
        plot_errors(records, summary, staging / PLOT_NAME)
    typer.echo(format_summary(summary))
    typer.echo(f"plot: {folder / PLOT_NAME}")


def _sampler(out_dir, document, touch_plan, random_positions, fixture_tolerance, anywhere):
    """simulate's TouchSampler on the fixture's STL (ValueError where the document lacks what it needs)."""
    from fixturecad.registration.deviations import tolerance_from_document
    from fixturecad.registration.features import faces_from_json, features_from_json
    from fixturecad.registration.sampling import TouchSampler, load_mesh

    features = {**features_from_json(document), **(faces_from_json(document) if anywhere else {})}
    tolerance = tolerance_from_document(features, document, fixture_tolerance)
    mesh = load_mesh(out_dir / "fixture.stl", document["volume_mm3"])
    return TouchSampler(document, mesh, touch_plan, random_positions, tolerance, anywhere)


def _trial_generator(seed, k):
    """Trial k's own random generator: a trial's touches are the same whichever process draws them."""
    import numpy as np

    return np.random.default_rng([seed, 2, k])


_WORKER = {}  # a worker process's routine, sampler and trial options (:func:`_start_worker`)


def _start_worker(sampling, options, seed):
    """A worker of simulate's pool. The parent answers Ctrl-C and SIGTERM, and says so; a worker whose parent
    has gone fails to send its trial and ends, and what it would say of that goes nowhere. A setup that fails
    is raised by the worker's first trial (a pool starts again, forever, a worker whose setup raises)."""
    import os
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    nowhere = os.open(os.devnull, os.O_WRONLY)
    os.dup2(nowhere, 2)
    os.close(nowhere)
    try:
        _WORKER.update(routine=load_routine(sampling[0]), sampler=_sampler(*sampling))
    except Exception as error:  # (whatever it is, the parent raises it with the first trial)
        _WORKER["error"] = error
    _WORKER.update(options=options, seed=seed)


def _worker_trial(k):
    """Trial k in a worker process (:func:`_start_worker`)."""
    if "error" in _WORKER:
        raise _WORKER["error"]
    return _trial(_WORKER["routine"], _WORKER["sampler"], _trial_generator(_WORKER["seed"], k), *_WORKER["options"])


def _designed_plan(out_dir: Path, name: str) -> dict:
    """{name: plan} of OUT_DIR/plans/NAME.json written by ``fixturecad plan``, {} if there is none."""
    import re

    from fixturecad.plan_commands import PLAN_NAME, PLANS_DIR

    path = out_dir / PLANS_DIR / f"{name}.json"
    if not re.fullmatch(PLAN_NAME, name) or not path.is_file():
        return {}  # the caller names the plans there are
    try:
        plan = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, RecursionError):
        plan = None
    if not isinstance(plan, dict) or not isinstance(plan.get("touch_plan"), list):
        raise InputError(f"{path} is not a touch plan of fixturecad plan: write it again")
    return {name: plan}


def _progress_stream():
    import io
    import sys

    return sys.stderr if sys.stderr.isatty() else io.StringIO()


def _trial(routine, sampler, rng, noise, sigma, nominal, lever, zone, unlabelled=False):
    """One registration of fresh synthetic touches: errors, status and the Cramer-Rao bound.

    On a printed part (``sampler.tolerance``), also the errors of a perfect
    part with the same noise and of the printed part without noise: each
    registered from a nominal pose near the truth, since they split the error
    of the right pose (what the search finds is the first registration's).
    """
    record = _registration(routine, sampler, rng, noise, sigma, nominal, lever, zone, True, unlabelled)
    if sampler.tolerance is not None:
        alone = _registration(routine, sampler, rng, noise, sigma, True, lever, zone, False, unlabelled, False)
        part = _registration(routine, sampler, rng, 0.0, sigma, True, lever, zone, True, unlabelled, False)
        record.update({f"noise_only_{key}": alone[key] for key in ("translation_error_mm", "rotation_error_deg")})
        record.update({f"fixture_only_{key}": part[key] for key in ("translation_error_mm", "rotation_error_deg")})
    return record


def _registration(routine, sampler, rng, noise, sigma, nominal, lever, zone, printed, unlabelled, bounds=True):
    """One registration of fresh touches: its status, errors and time, and (``bounds``) the Cramer-Rao bounds of
    its touches, on the part and on a perfect one."""
    import time

    import numpy as np

    from fixturecad.registration.problem import Problem
    from fixturecad.registration.touches import build_groups
    from fixturecad.registration.uncertainty import cramer_rao_bound, sigmas
    from fixturecad.registration.pose import apply_twist, fixture2meas_from_rt, pose_errors

    tolerance = sampler.tolerance
    deviations = None
    if tolerance is not None:
        # A perfect part is the model's own features (an as-built folder's are not the mesh's).
        deviations = tolerance.random_deviations(rng) if printed else {
            fid: np.zeros(len(m.names)) for fid, m in tolerance.modes.items()}
    touches, contacts, truth = sampler.draw(rng, noise, lever_mm=lever, printed=deviations)
    initial = None
    if nominal:
        twist = np.concatenate([np.radians(1.0) * _unit(rng), 1.0 * _unit(rng)])
        initial = fixture2meas_from_rt(*apply_twist(truth[:3, :3], truth[:3, 3], twist))
    start = time.perf_counter()
    # Unlabelled: the point touches without their features (the routine's numbering: after the contacts).
    given = {"touches": {}, "unlabelled": np.concatenate(list(touches.values()))} if unlabelled else {"touches": touches}
    if sampler.anywhere is not None:  # drawn anywhere on the part: registered on any face
        given["anywhere"] = True
    result = routine.register(**given, initial_pose=initial, sigma_mm=sigma, ball_radius_mm=sampler.ball_radius_mm,
                              contacts=contacts, lever_mm=lever, fixture_tolerance_mm=zone)
    elapsed = time.perf_counter() - start
    # An inconsistent result with no explanation gives no pose: no error to count.
    err_t, err_r = (np.nan, np.nan) if result["pose"] is None else pose_errors(np.array(result["pose"]), truth)
    # The bound of the noise actually drawn (the routine's sigma also allows for the STL's chords).
    # Unlabelled: each touch's feature against the one the answer put it on (None: none, or left out).
    own = [fid for fid, points in touches.items() for _ in range(len(points))]
    put = {a["touch"] - len(contacts): a["feature"] for a in result.get("assignment") or []}
    record = {
        "status": result["status"],
        **({"assigned": [[fid, put.get(k)] for k, fid in enumerate(own)]} if unlabelled else {}),
        "translation_error_mm": err_t,
        "rotation_error_deg": float(np.degrees(err_r)),
        "time_s": elapsed,
    }
    if bounds:
        noise_model = noise if noise > 0 else sigma
        groups = build_groups(sampler.features, touches, sampler.ball_radius_mm, contacts)
        bound_t, bound_r = sigmas(cramer_rao_bound(Problem(groups, noise_model, lever, tolerance), truth, noise_model))
        noise_t, noise_r = sigmas(cramer_rao_bound(Problem(groups, noise_model, lever), truth, noise_model))
        record.update(crb_translation_mm=bound_t, crb_rotation_deg=bound_r, noise_crb_translation_mm=noise_t,
                      noise_crb_rotation_deg=noise_r)
    return record


def _check_tolerance(zone):
    if zone is not None and not (zone >= 0 and zone < float("inf")):
        raise InputError(f"--fixture-tolerance must be a non-negative number of mm, got {zone}")


def _unit(rng):
    import numpy as np

    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def summarise(records, noise):
    """Median, 95th percentile and RMS of the errors (of the trials that gave a pose), the bound's RMS (of those
    not underdetermined), success rate, ratio of RMS error to the bound over the trials that call their pose
    unique (an ambiguous trial's pose may be another that fits as well, an underdetermined one's is not
    claimed)."""
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
    rms_t, rms_r = float(np.sqrt(np.nanmean(et**2))), float(np.sqrt(np.nanmean(er**2)))
    # An underdetermined trial's touches leave a motion free: its bound has no size to average (unless all are).
    sized = np.array([r["status"] != "underdetermined" for r in records])
    sized = sized if sized.any() else ~sized
    crb_t, crb_r = float(np.sqrt(np.nanmean(bt[sized] ** 2))), float(np.sqrt(np.nanmean(br[sized] ** 2)))
    unique = np.array([r["status"] == "unique" for r in records])

    def unique_rms(values):
        return float(np.sqrt(np.nanmean(values[unique] ** 2))) if unique.any() else None

    on_unique = {"unique_rms_translation_error_mm": unique_rms(et), "unique_rms_rotation_error_deg": unique_rms(er),
                 "unique_crb_translation_mm": unique_rms(bt), "unique_crb_rotation_deg": unique_rms(br)}
    ratio = noise > 0 and unique.any()
    return {
        "median_translation_error_mm": float(np.nanmedian(et)),
        "p95_translation_error_mm": float(np.nanpercentile(et, 95)),
        "median_rotation_error_deg": float(np.nanmedian(er)),
        "p95_rotation_error_deg": float(np.nanpercentile(er, 95)),
        "rms_translation_error_mm": rms_t,
        "rms_rotation_error_deg": rms_r,
        "crb_translation_mm": crb_t,
        "crb_rotation_deg": crb_r,
        "unique_trials": int(unique.sum()),
        **on_unique,
        "ratio_translation_to_crb": on_unique["unique_rms_translation_error_mm"] / on_unique["unique_crb_translation_mm"]
        if ratio else None,
        "ratio_rotation_to_crb": on_unique["unique_rms_rotation_error_deg"] / on_unique["unique_crb_rotation_deg"]
        if ratio else None,
        "success_rate": float(success.mean()),
        "statuses": statuses,
        "median_time_ms": float(np.median([r["time_s"] for r in records]) * 1e3),
        **_split(records),
        **({"assigned_own_feature": float(np.mean([own == put for r in records for own, put in r["assigned"]]))}
           if "assigned" in records[0] else {}),
    }


def _split(records):
    """RMS errors from the touch noise alone and from the printed part alone, when simulated."""
    import numpy as np

    out = {}
    if "noise_only_translation_error_mm" in records[0]:
        for key, unit in (("translation", "mm"), ("rotation", "deg")):
            bound = np.array([r[f"noise_crb_{key}_{unit}"] for r in records], dtype=float)
            out[f"noise_crb_{key}_{unit}"] = float(np.sqrt(np.nanmean(bound**2)))
    for source in ("noise_only", "fixture_only"):
        if f"{source}_translation_error_mm" in records[0]:
            for key, unit in (("translation_error", "mm"), ("rotation_error", "deg")):
                values = np.array([r[f"{source}_{key}_{unit}"] for r in records])
                out[f"{source}_rms_{key}_{unit}"] = float(np.sqrt(np.nanmean(values**2)))
    return out


def format_summary(s) -> str:
    ratio = (
        f"RMS error / Cramer-Rao bound{' (touch noise and fixture)' if s['fixture_tolerance_mm'] is not None else ''}"
        f" over the {s['unique_trials']} unique trials: "
        f"translation {s['ratio_translation_to_crb']:.3f}, rotation {s['ratio_rotation_to_crb']:.3f}"
        if s["ratio_translation_to_crb"] is not None
        else "noise 0: no Cramer-Rao ratio" if s["noise_mm"] == 0 else "no unique trial: no Cramer-Rao ratio"
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
        *([f"fixture tolerance: {s['fixture_tolerance_mm']:g} mm" if not s["calibrated"] else "as-built part (calibrated)",
           "RMS error from the touch noise (a perfect part, from near the true pose): "
           f"{s['noise_only_rms_translation_error_mm'] * 1e3:.2f} um, {s['noise_only_rms_rotation_error_deg'] * 1e3:.3f} mdeg",
           "RMS error from the printed part (no noise, from near the true pose): "
           f"{s['fixture_only_rms_translation_error_mm'] * 1e3:.2f} um, {s['fixture_only_rms_rotation_error_deg'] * 1e3:.3f} mdeg",
           f"RMS error in all: {s['rms_translation_error_mm'] * 1e3:.2f} um, {s['rms_rotation_error_deg'] * 1e3:.3f} mdeg "
           f"({s['rms_translation_error_mm'] / s['noise_crb_translation_mm']:.2f} x, "
           f"{s['rms_rotation_error_deg'] / s['noise_crb_rotation_deg']:.2f} x the touch-noise bound "
           f"{s['noise_crb_translation_mm'] * 1e3:.2f} um, {s['noise_crb_rotation_deg'] * 1e3:.3f} mdeg)"]
          if "noise_only_rms_translation_error_mm" in s else []),
        *([f"unlabelled: {100 * s['assigned_own_feature']:.1f} % of the touches put on the feature they were "
           "made on"] if s.get("unlabelled") else []),
        f"median registration time: {s['median_time_ms']:.2f} ms",
    ])


def _plot_assignment(ax, assigned):
    """Unlabelled touches: how many made on each feature (rows) the answers put on each feature (columns)."""
    import numpy as np

    rows = sorted({own for own, _ in assigned})
    columns = rows + sorted({put for _, put in assigned if put is not None and put not in rows}) + ["none"]
    counts = np.zeros((len(rows), len(columns)), int)
    for own, put in assigned:
        counts[rows.index(own), columns.index("none" if put is None else put)] += 1
    ax.imshow(counts, cmap="Greens")
    for (i, j), n in np.ndenumerate(counts):
        if n:
            ax.text(j, i, str(n), ha="center", va="center", color="white" if n > counts.max() / 2 else "black")
    ax.set_xticks(range(len(columns)), columns, rotation=30, ha="right")
    ax.set_yticks(range(len(rows)), rows)
    ax.set_xlabel("put on (the answer's assignment)")
    ax.set_ylabel("made on")
    ax.set_title("unlabelled touches")


def plot_errors(records, summary, path: Path) -> None:
    """Histograms of the translation and rotation errors with the RMS bound marked: of the trials that call their
    pose unique where there are any (an ambiguous or underdetermined trial's pose is not claimed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.ticker import MaxNLocator

    assigned = [pair for r in records for pair in r.get("assigned", ())]
    fig, axes = plt.subplots(1, 3 if assigned else 2, figsize=(15, 4.6) if assigned else (10, 4))
    panels = [("translation_error_mm", 1e3, "translation error (um)", "crb_translation_mm"),
              ("rotation_error_deg", 1e3, "rotation error (mdeg)", "crb_rotation_deg")]
    some = 0 < summary["unique_trials"] < summary["trials"]
    if summary["unique_trials"]:
        records = [r for r in records if r["status"] == "unique"]
        panels = [(key, scale, label + (f", the {summary['unique_trials']} unique trials" if some else ""), bound)
                  for key, scale, label, bound in panels]
    else:
        # Every pose shown is one of several that fit, not a claimed one; an underdetermined trial's pose is not
        # even that (its touches leave a motion free: its bound has no size), unless there is nothing else.
        records = [r for r in records if r["status"] != "underdetermined"] or records
        panels = [(key, scale, label + ", no unique trial: each one's first pose", bound)
                  for key, scale, label, bound in panels]
    for ax, (key, scale, label, bound) in zip(axes, panels):
        values = np.array([r[key] for r in records]) * scale
        bounds = np.array([np.nan if r[bound] is None else r[bound] for r in records]) * scale
        ax.hist(values, bins=40, color="0.7")
        ax.axvline(np.sqrt(np.nanmean(bounds**2)), color="tab:red", label="Cramer-Rao bound (RMS)")
        ax.axvline(np.sqrt(np.nanmean(values**2)), color="tab:blue", linestyle="--", label="observed RMS")
        ax.set_xlabel(label)
        ax.set_ylabel("trials")
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))  # counts of trials
        ax.xaxis.set_major_locator(MaxNLocator(6))  # wide errors' long labels would run together
        ax.legend()
    if assigned:
        _plot_assignment(axes[2], assigned)
    part = ("an as-built part" if summary["calibrated"] else "an exact part" if summary["fixture_tolerance_mm"] is None
            else f"parts printed within {summary['fixture_tolerance_mm']:g} mm (the bound counts the print)")
    touches = " of unlabelled touches anywhere" if summary.get("anywhere") else " of unlabelled touches" if assigned else ""
    fig.suptitle(f"{summary['trials']} trials{touches} on {part}, "
                 f"noise {summary['noise_mm']} mm, "
                 f"success {100 * summary['success_rate']:.1f} %")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
