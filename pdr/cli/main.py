"""The ``pdr`` command line (thin: parse, call a pipeline, print). See CONTRACT.md for the public face.

Exit codes: 0 success; 1 bad input (one ``error:`` line on stderr); 2 usage error. ``--debug`` shows the traceback.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import textwrap
import warnings
from pathlib import Path

from pdr import __version__
from pdr.errors import LOGGER_NAME, InputError, warn

HELP_WIDTH = 100  # characters per line of the --help texts
IMPORT_FORMATS = ("oxford", "mobgap", "humolire", "gaitmap", "xio", "sensorlogger", "phyphox", "gpx", "openshoe")


def _cmd_import(args: argparse.Namespace) -> int:
    from pdr.io.importers import import_recordings

    for path in import_recordings(args.format, Path(args.src), Path(args.dest), rate_hz=args.rate_hz, force=args.force,
                                  foot=args.foot, closed_loop=args.closed_loop):
        print(path)
    return 0


def _cmd_validate(args: argparse.Namespace) -> int:
    from pdr.pipelines.check import check_recording

    from pdr.pipelines.not_walking import min_step_rate_hz

    rec = check_recording(args.rec)
    if rec.sample_rate_hz < min_step_rate_hz():
        warn(f"{rec.id}: sampling rate {rec.sample_rate_hz:.1f} Hz is below twice the highest cadence "
             f"({min_step_rate_hz():g} Hz): no step can be found; pdr run follows the GNSS alone")
    parts = [f"{len(rec.imu)} IMU samples at {rec.sample_rate_hz:.1f} Hz", f"placement {rec.placement}"]
    parts += [f"imu_{k}" for k in rec.extra_imus]
    if rec.gnss is not None:
        parts.append(f"{len(rec.gnss)} GNSS fixes")
    if rec.video_path is not None:
        parts.append(rec.video_path.name)
    if rec.reference:
        parts.append("reference: " + ", ".join(sorted(rec.reference)))
    print(f"ok: {rec.id}: " + "; ".join(parts))
    return 0


def _cmd_steps(args: argparse.Namespace) -> int:
    from pdr.config import load_config
    from pdr.io.atomic import write_csv
    from pdr.io.recording import load_recording
    from pdr.pipelines.steps import detect_steps

    rec = load_recording(args.rec, with_reference=False)
    steps = detect_steps(rec, load_config(args.config))
    write_csv(args.output, steps)
    print(f"{len(steps)} steps -> {args.output}")
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    from pdr.pipelines.run import run_recording

    summary = run_recording(
        Path(args.rec), Path(args.output), config_path=args.config, model_path=args.model,
        use_gnss=not args.no_gnss, plot=args.plot, force=args.force,
    )
    print(summary["one_line"])
    return 0


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from pdr.pipelines.calibrate import calibrate_recordings

    print(calibrate_recordings([Path(r) for r in args.recs], Path(args.output), config_path=args.config,
                               distance_m=args.distance_m, landmarks=args.landmarks, trajectory=args.trajectory))
    return 0


def _cmd_simulate(args: argparse.Namespace) -> int:
    from pdr.sim import simulate_to_disk

    print(simulate_to_disk(Path(args.config), Path(args.output), seed=args.seed, force=args.force))
    return 0


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from pdr.eval import evaluate_run

    print(json.dumps(evaluate_run(Path(args.out), Path(args.rec)), indent=2, sort_keys=True))
    return 0


def _cmd_batch(args: argparse.Namespace) -> int:
    from pdr.pipelines.batch import run_batch

    print(run_batch([Path(r) for r in args.recs], Path(args.output), engine=args.engine, workers=args.workers,
                    scheduler=args.scheduler, config_path=args.config, model_path=args.model, use_gnss=not args.no_gnss))
    return 0


def _cmd_gait_forms(args: argparse.Namespace) -> int:
    from pdr.pipelines import gait_forms

    if args.action == "fit":
        print(gait_forms.fit_forms([Path(r) for r in args.recs], Path(args.output), config_path=args.config))
    else:
        print(gait_forms.classify_forms(Path(args.rec), Path(args.forms), Path(args.output), config_path=args.config))
    return 0


def _cmd_gait_camera(args: argparse.Namespace) -> int:
    from pdr.pipelines import gait_camera

    if args.action == "simulate":
        print(gait_camera.simulate_thigh_camera_to_disk(Path(args.config), Path(args.output), seed=args.seed, force=args.force))
    elif args.action == "fit":
        print(gait_camera.fit_templates([Path(m) for m in args.mocap], Path(args.output)))
    elif args.action == "estimate":
        print(gait_camera.estimate_gait(Path(args.folder), Path(args.templates), Path(args.output), force=args.force))
    else:
        print(json.dumps(gait_camera.evaluate_gait(Path(args.out), Path(args.folder)), indent=2, sort_keys=True))
    return 0


def _cmd_datasets(args: argparse.Namespace) -> int:
    from pdr.io import datasets

    if args.action == "list":
        root = datasets.data_dir()
        print(f"data folder: {root} (set {datasets.DATA_DIR_VARIABLE} to change it)")
        for name, ds in sorted(datasets.load_registry().items()):
            missing = datasets.missing_files(name, root)
            state = "present" if not missing else f"missing {len(missing)} of {len(ds.files)} files"
            print(f"{name}: {ds.title}. {ds.licence}; {ds.repository} @ {ds.commit[:12]}; truth: {ds.ground_truth} [{state}]")
    elif args.action == "path":
        print(datasets.dataset_dir(args.name))
    else:
        for name in args.names:
            print(datasets.fetch_dataset(name, Path(args.dir) if args.dir else None))
    return 0


def _positive_int(text: str) -> int:
    """argparse type: an integer >= 1 (anything else is a usage error, exit 2)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, found {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, found {text!r}")
    return value


def _positive_float(text: str) -> float:
    """argparse type: a finite number > 0 (anything else is a usage error, exit 2)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number > 0, found {text!r}") from None
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected a number > 0, found {text!r}")
    return value


def _command(sub, name: str, summary: str, description: str, writes: str, example: str, common) -> argparse.ArgumentParser:
    """A (sub)command whose --help says what it does, the files it writes and one example."""
    return sub.add_parser(name, help=summary, description=textwrap.fill(description, HELP_WIDTH), parents=[common],
                          formatter_class=argparse.RawDescriptionHelpFormatter,
                          epilog=f"{textwrap.fill('writes: ' + writes, HELP_WIDTH)}\n\nexample:\n  {example}")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="pdr", description="Pedestrian dead reckoning by sensor fusion.",
                                     epilog="pdr COMMAND --help describes each command. Exit codes: 0 success, "
                                            "1 bad input (one error: line), 2 usage error.")
    parser.add_argument("--version", action="version", version=f"pdr {__version__}")
    parser.add_argument("--debug", action="store_true", help="show the traceback on errors")
    # --debug is accepted after the command too; SUPPRESS keeps a value given before it
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show the traceback on errors")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    config_help = "TOML configuration file (sections [steps], [heading], [step_length], [fusion], ...; default: built-in)"

    p = _command(sub, "import", "convert another format into canonical recordings",
                 "Convert a recording of another format (FORMAT) into canonical recordings under DEST (one folder each) "
                 "and print their paths, one a line. Ground truth found in the source goes to reference/.",
                 "DEST/<recording>/ (meta.toml, imu.csv, optional gnss.csv, reference/); gpx adds gnss.csv to the "
                 "recording DEST", "pdr import oxford Oxford_step_counter/walk.csv recordings/", common)
    p.add_argument("format", choices=IMPORT_FORMATS, help="source format: " + ", ".join(IMPORT_FORMATS))
    p.add_argument("src", help="the source file or folder (for gpx: the .gpx track)")
    p.add_argument("dest", help="the folder to write recordings into (for gpx: the recording to add gnss.csv to)")
    p.add_argument("--rate-hz", type=_positive_float, default=None,
                   help="sampling rate (Hz) of sources that carry only a sample index (gaitmap: 204.8 or 102.4)")
    p.add_argument("--force", action="store_true", help="replace recordings that already exist")
    p.add_argument("--foot", choices=("left", "right"), default=None,
                   help="the foot of a single-foot IMU file (openshoe, xio), when its name does not say")
    p.add_argument("--closed-loop", action="store_true",
                   help="the walk ends where it started (written to reference/; xio, openshoe)")
    p.set_defaults(func=_cmd_import)

    p = _command(sub, "validate", "check a recording against CONTRACT.md",
                 "Check a recording against CONTRACT.md: every file pdr run reads (meta.toml, imu*.csv, gnss.csv, "
                 "camera.toml and every frame of the video) and reference/. Prints one ok: line with what was "
                 "found, or one error: line (exit 1).", "nothing", "pdr validate out/demo_recording", common)
    p.add_argument("rec", help="the recording folder")
    p.set_defaults(func=_cmd_validate)

    p = _command(sub, "steps", "detect steps",
                 "Detect the steps of a recording's main IMU (the instant of each foot contact).",
                 "the CSV file -o (t_s in seconds, one row per step, plus the detector's columns)",
                 "pdr steps out/demo_recording -o steps.csv", common)
    p.add_argument("rec", help="the recording folder")
    p.add_argument("-o", "--output", required=True, help="the steps CSV file to write")
    p.add_argument("--config", default=None, help=config_help)
    p.set_defaults(func=_cmd_steps)

    p = _command(sub, "run", "the full reconstruction",
                 "Reconstruct the walk of a recording with every sensor it has (steps, step lengths, strides, "
                 "heading, GNSS fused in a factor graph) and print a one-line summary. Positions in metres east and "
                 "north of the start (or of the [geo] origin), heading in radians counter-clockwise from east.",
                 "OUT/steps.csv, trajectory.csv, trajectory.geojson, trajectory.tum, summary.json, run.json; "
                 "strides.csv with a leg camera or foot IMU; trajectory.gpx with a geo origin; trajectory.png with "
                 "--plot. An existing OUT needs --force, which replaces only these files",
                 "pdr run out/demo_recording -o out/demo --plot", common)
    p.add_argument("rec", help="the recording folder")
    p.add_argument("-o", "--output", required=True, help="the output folder OUT")
    p.add_argument("--config", default=None, help=config_help)
    p.add_argument("--model", default=None, help="per-user step model (model.json from pdr calibrate)")
    p.add_argument("--no-gnss", action="store_true", help="ignore gnss.csv")
    p.add_argument("--plot", action="store_true", help="write trajectory.png")
    p.add_argument("--force", action="store_true",
                   help="write into an existing OUT, replacing the files pdr run writes (other files are kept)")
    p.set_defaults(func=_cmd_run)

    p = _command(sub, "calibrate", "fit the per-user step-length model",
                 "Fit the per-user step-length model (metres per step from step frequency in Hz and signal "
                 "variance) from the GNSS of the recordings, or from known distances: --distance-m, --landmarks or "
                 "--trajectory for the k-th recording.", "the JSON file -o (what pdr run --model takes)",
                 "pdr calibrate walk1 corridor -o model.json --distance-m 60", common)
    p.add_argument("recs", nargs="+", help="recording folders (with gnss.csv unless a known distance is given)")
    p.add_argument("-o", "--output", required=True, help="the model JSON file to write")
    p.add_argument("--config", default=None, help=config_help)
    p.add_argument("--distance-m", type=_positive_float, action="append", metavar="D",
                   help="the k-th recording's walk was D metres (repeat per recording; others use GNSS)")
    p.add_argument("--landmarks", action="append", metavar="CSV",
                   help="the k-th recording passed these surveyed points (t_s, e_m, n_m) in turn")
    p.add_argument("--trajectory", action="append", metavar="CSV",
                   help="the k-th recording's reference path (t_s, e_m, n_m)")
    p.set_defaults(func=_cmd_calibrate)

    p = _command(sub, "simulate", "write a synthetic recording with its reference/",
                 "Simulate a walk described by a scenario TOML (route in metres, speeds in m/s, durations in s, "
                 "sensors and their errors) and write it as a recording with its ground truth.",
                 "the recording folder -o (meta.toml, imu*.csv, gnss.csv, video, reference/)",
                 "pdr simulate configs/sim/walk_short.toml -o rec --seed 1", common)
    p.add_argument("config", help="the scenario TOML (see configs/sim/)")
    p.add_argument("-o", "--output", required=True, help="the recording folder to write")
    p.add_argument("--seed", type=int, default=0, help="random seed (the same seed gives the same recording)")
    p.add_argument("--force", action="store_true", help="replace an existing recording")
    p.set_defaults(func=_cmd_simulate)

    p = _command(sub, "evaluate", "metrics of a run output against the recording's reference/",
                 "Print a JSON object of metrics of a pdr run output against the recording's reference/: step "
                 "counts (step_count_error and step_count_error_pct signed: estimate minus reference), step timing "
                 "F1, distance error (%), ATE RMSE and final error (m and % of the distance).",
                 "nothing (the JSON goes to stdout)", "pdr evaluate out/demo out/demo_recording", common)
    p.add_argument("out", help="the pdr run output folder")
    p.add_argument("rec", help="the recording folder with reference/")
    p.set_defaults(func=_cmd_evaluate)

    p = _command(sub, "batch", "run over many recordings",
                 "pdr run over many recordings: OUT/<recording id>/ each, plus OUT/summary.csv. "
                 "A second run skips complete outputs made with the same options.",
                 "OUT/<recording id>/ (the pdr run outputs) and OUT/summary.csv (recording_id, recording_path, "
                 "status, distance_m, n_steps, duration_s, error), rewritten as each recording finishes",
                 "pdr batch recordings/* -o out/batch --workers 2", common)
    p.add_argument("recs", nargs="+", help="recording folders")
    p.add_argument("-o", "--output", required=True, help="the output folder OUT")
    p.add_argument("--engine", choices=("local", "dask"), default="local",
                   help="local process pool (default) or Dask distributed")
    p.add_argument("--workers", type=_positive_int, default=None,
                   help="worker processes (local pool or the Dask LocalCluster; default: the CPUs available)")
    p.add_argument("--scheduler", default=None,
                   help="address of an existing Dask scheduler (tcp://HOST:PORT; with --engine dask)")
    p.add_argument("--config", default=None, help=config_help)
    p.add_argument("--model", default=None, help="per-user step model (model.json from pdr calibrate)")
    p.add_argument("--no-gnss", action="store_true", help="ignore gnss.csv")
    p.set_defaults(func=_cmd_batch)

    p = _command(sub, "gait-forms", "walking forms from Fourier gait features",
                 "Learn walking forms (fit) or label the gait cycles of a recording with them (classify).",
                 "fit: forms.json; classify: forms.csv (t_start_s, t_end_s, form)",
                 "pdr gait-forms fit walk1 walk2 -o forms.json", common)
    gsub = p.add_subparsers(dest="action", required=True, metavar="ACTION", help="fit: learn forms; classify: label a recording")
    forms_config = "TOML: [gait_forms], [steps], [step_length]"
    g = _command(gsub, "fit", "learn walking forms", "Learn walking forms from the gait cycles of the recordings.",
                 "the JSON file -o", "pdr gait-forms fit walk1 walk2 -o forms.json", common)
    g.add_argument("recs", nargs="+", help="recording folders")
    g.add_argument("-o", "--output", required=True, help="the forms JSON file to write")
    g.add_argument("--config", default=None, help=forms_config)
    g = _command(gsub, "classify", "label gait cycles", "Label each gait cycle of a recording with a walking form.",
                 "the CSV file -o (t_start_s, t_end_s in seconds, form)",
                 "pdr gait-forms classify walk3 --forms forms.json -o forms.csv", common)
    g.add_argument("rec", help="the recording folder")
    g.add_argument("--forms", required=True, help="forms.json from pdr gait-forms fit")
    g.add_argument("-o", "--output", required=True, help="the CSV file to write")
    g.add_argument("--config", default=None, help=forms_config)
    p.set_defaults(func=_cmd_gait_forms)

    p = _command(sub, "gait-camera", "walking state, form and body pose from a thigh camera (Watanabe et al.)",
                 "Simulate, fit templates for, track and evaluate thigh-camera folders.",
                 "simulate: a folder; fit: templates JSON; estimate: an output folder; evaluate: nothing (JSON on stdout)",
                 "pdr gait-camera simulate configs/sim/thigh_camera.toml -o thigh --seed 1", common)
    gsub = p.add_subparsers(dest="action", required=True, metavar="ACTION", help="simulate, fit, estimate or evaluate")
    g = _command(gsub, "simulate", "a simulated thigh-camera folder with its reference/",
                 "Simulate a thigh-camera folder from a scenario TOML.", "the folder -o (camera.toml, frames.csv, "
                 "observations, reference/)", "pdr gait-camera simulate configs/sim/thigh_camera.toml -o thigh --seed 1",
                 common)
    g.add_argument("config", help="the scenario TOML")
    g.add_argument("-o", "--output", required=True, help="the folder to write")
    g.add_argument("--seed", type=int, default=0, help="random seed")
    g.add_argument("--force", action="store_true", help="replace an existing folder")
    g = _command(gsub, "fit", "per-form templates from motion-capture tables (one walk per file)",
                 "Fit per-form joint-angle templates (radians over the gait cycle) from motion-capture tables.",
                 "the templates JSON file -o", "pdr gait-camera fit walk.csv run.csv -o templates.json", common)
    g.add_argument("mocap", nargs="+", help="motion-capture CSV tables, one walk per file")
    g.add_argument("-o", "--output", required=True, help="the templates JSON file to write")
    g = _command(gsub, "estimate", "track a thigh-camera folder",
                 "Track a thigh-camera folder: walking state, form and body pose per frame.",
                 "the output folder -o", "pdr gait-camera estimate thigh --templates templates.json -o thigh_out", common)
    g.add_argument("folder", help="the thigh-camera folder")
    g.add_argument("--templates", required=True, help="templates JSON from pdr gait-camera fit")
    g.add_argument("-o", "--output", required=True, help="the output folder to write")
    g.add_argument("--force", action="store_true", help="replace an existing output folder")
    g = _command(gsub, "evaluate", "metrics of an estimate against the folder's reference/",
                 "Print a JSON object of metrics of an estimate against the folder's reference/.",
                 "nothing (the JSON goes to stdout)", "pdr gait-camera evaluate thigh_out thigh", common)
    g.add_argument("out", help="the output folder of pdr gait-camera estimate")
    g.add_argument("folder", help="the thigh-camera folder with reference/")
    p.set_defaults(func=_cmd_gait_camera)

    p = _command(sub, "datasets", "the public recordings of the registry (datasets/registry.toml)",
                 "List the registered public recordings, or download them with their checksums "
                 "verified. PDR_DATA_DIR points pdr at a local copy (default: ../shared/datasets "
                 "beside the repository, else the download cache).",
                 "fetch: the dataset's files under the cache (or --dir); list and path: nothing",
                 "pdr datasets fetch humolire_phone_landmarks --dir data", common)
    gsub = p.add_subparsers(dest="action", required=True, metavar="ACTION", help="list, path or fetch")
    _command(gsub, "list", "each dataset: source, licence, ground truth, and whether its files are present",
             "List each registered dataset: source, licence, ground truth, and whether its files are present.",
             "nothing", "pdr datasets list", common)
    g = _command(gsub, "path", "print the local folder of a dataset (an error that says how to get it if absent)",
                 "Print the local folder of a dataset (an error that says how to get it if absent).", "nothing",
                 "pdr datasets path humolire_phone_landmarks", common)
    g.add_argument("name", metavar="NAME", help="a dataset name from pdr datasets list")
    g = _command(gsub, "fetch", "download datasets into the cache (or --dir) and verify each sha256",
                 "Download datasets into the cache (or --dir) and verify the sha256 of every file.",
                 "DIR/NAME/ with the dataset's files", "pdr datasets fetch humolire_phone_landmarks --dir data", common)
    g.add_argument("names", nargs="+", metavar="NAME", help="dataset names from pdr datasets list")
    g.add_argument("--dir", default=None, help="destination folder (default: the download cache)")
    p.set_defaults(func=_cmd_datasets)
    return parser


def _report_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """The CLI's reporter of the Python warnings of the libraries underneath: each a ``warning:`` line on stderr."""
    print(f"warning: {' '.join(str(message).split())}", file=sys.stderr)


class _WarningLines(logging.Handler):
    """The CLI's reporter of the library's warnings (the ``pdr`` logger): each a ``warning:`` line on stderr."""

    def emit(self, record: logging.LogRecord) -> None:
        print(f"warning: {record.getMessage()}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logger = logging.getLogger(LOGGER_NAME)
    reporter, saved = _WarningLines(logging.WARNING), (logger.propagate, logger.level)
    logger.addHandler(reporter)
    logger.propagate = False  # the CLI's lines only, not also the application's root handlers
    logger.setLevel(logging.WARNING)
    try:
        with warnings.catch_warnings():  # every warning of the command to stderr, none left to the caller's filters
            warnings.simplefilter("always")
            warnings.showwarning = _report_warning
            return int(args.func(args) or 0)
    except InputError as exc:
        if args.debug:
            raise
        print(f"error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # an internal failure still gets one line, and the traceback behind --debug
        if args.debug:
            raise
        print(f"error: internal failure {type(exc).__name__}: {' '.join(str(exc).split())[:300]} (rerun with --debug)", file=sys.stderr)
        return 1
    finally:
        logger.removeHandler(reporter)
        logger.propagate, level = saved
        logger.setLevel(level)


def entry_point() -> None:
    sys.exit(main())
