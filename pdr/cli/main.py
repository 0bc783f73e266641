"""The ``pdr`` command line (thin: parse, call a pipeline, print). See CONTRACT.md for the public face.

Exit codes: 0 success; 1 bad input (one ``error:`` line on stderr); 2 usage error. ``--debug`` shows the traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

from pdr import __version__
from pdr.errors import InputError

IMPORT_FORMATS = ("oxford", "mobgap", "humolire", "gaitmap", "xio", "sensorlogger", "phyphox", "gpx")


def _cmd_import(args: argparse.Namespace) -> int:
    from pdr.io.importers import import_recordings

    for path in import_recordings(args.format, Path(args.src), Path(args.dest), rate_hz=args.rate_hz, force=args.force):
        print(path)
    return 0


def _cmd_validate(args: argparse.Namespace) -> int:
    from pdr.pipelines.check import check_recording

    rec = check_recording(args.rec)
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

    print(calibrate_recordings([Path(r) for r in args.recs], Path(args.output), config_path=args.config))
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


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="pdr", description="Pedestrian dead reckoning by sensor fusion.")
    parser.add_argument("--version", action="version", version=f"pdr {__version__}")
    parser.add_argument("--debug", action="store_true", help="show the traceback on errors")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("import", help="convert another format into canonical recordings")
    p.add_argument("format", choices=IMPORT_FORMATS)
    p.add_argument("src")
    p.add_argument("dest")
    p.add_argument("--rate-hz", type=float, default=None, help="sampling rate of sources that carry only a sample index")
    p.add_argument("--force", action="store_true", help="replace recordings that already exist")
    p.set_defaults(func=_cmd_import)

    p = sub.add_parser("validate", help="check a recording against CONTRACT.md")
    p.add_argument("rec")
    p.set_defaults(func=_cmd_validate)

    p = sub.add_parser("steps", help="detect steps")
    p.add_argument("rec")
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--config", default=None)
    p.set_defaults(func=_cmd_steps)

    p = sub.add_parser("run", help="the full reconstruction")
    p.add_argument("rec")
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--config", default=None)
    p.add_argument("--model", default=None, help="per-user step model from `pdr calibrate`")
    p.add_argument("--no-gnss", action="store_true", help="ignore gnss.csv")
    p.add_argument("--plot", action="store_true", help="write trajectory.png")
    p.add_argument("--force", action="store_true", help="replace an existing output folder")
    p.set_defaults(func=_cmd_run)

    p = sub.add_parser("calibrate", help="fit the per-user step-length model")
    p.add_argument("recs", nargs="+")
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--config", default=None)
    p.set_defaults(func=_cmd_calibrate)

    p = sub.add_parser("simulate", help="write a synthetic recording with its reference/")
    p.add_argument("config")
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--force", action="store_true")
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser("evaluate", help="metrics of a run output against the recording's reference/")
    p.add_argument("out")
    p.add_argument("rec")
    p.set_defaults(func=_cmd_evaluate)

    p = sub.add_parser("batch", help="run over many recordings",
                       description="pdr run over many recordings: OUT/<recording id>/ each, plus OUT/summary.csv. "
                                   "A second run skips complete outputs made with the same options.")
    p.add_argument("recs", nargs="+")
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--engine", choices=("local", "dask"), default="local",
                   help="local process pool (default) or Dask distributed")
    p.add_argument("--workers", type=int, default=None,
                   help="worker processes (local pool or the Dask LocalCluster; default: the CPUs available)")
    p.add_argument("--scheduler", default=None,
                   help="address of an existing Dask scheduler (tcp://HOST:PORT; with --engine dask)")
    p.add_argument("--config", default=None)
    p.add_argument("--model", default=None)
    p.add_argument("--no-gnss", action="store_true")
    p.set_defaults(func=_cmd_batch)

    p = sub.add_parser("gait-forms", help="walking forms from Fourier gait features")
    gsub = p.add_subparsers(dest="action", required=True)
    g = gsub.add_parser("fit")
    g.add_argument("recs", nargs="+")
    g.add_argument("-o", "--output", required=True)
    g.add_argument("--config", default=None, help="TOML: [gait_forms], [steps], [step_length]")
    g = gsub.add_parser("classify")
    g.add_argument("rec")
    g.add_argument("--forms", required=True)
    g.add_argument("-o", "--output", required=True)
    g.add_argument("--config", default=None, help="TOML: [gait_forms], [steps], [step_length]")
    p.set_defaults(func=_cmd_gait_forms)

    p = sub.add_parser("gait-camera", help="walking state, form and body pose from a thigh camera (Watanabe et al.)")
    gsub = p.add_subparsers(dest="action", required=True)
    g = gsub.add_parser("simulate", help="a simulated thigh-camera folder with its reference/")
    g.add_argument("config")
    g.add_argument("-o", "--output", required=True)
    g.add_argument("--seed", type=int, default=0)
    g.add_argument("--force", action="store_true")
    g = gsub.add_parser("fit", help="per-form templates from motion-capture tables (one walk per file)")
    g.add_argument("mocap", nargs="+")
    g.add_argument("-o", "--output", required=True)
    g = gsub.add_parser("estimate", help="track a thigh-camera folder")
    g.add_argument("folder")
    g.add_argument("--templates", required=True)
    g.add_argument("-o", "--output", required=True)
    g.add_argument("--force", action="store_true")
    g = gsub.add_parser("evaluate", help="metrics of an estimate against the folder's reference/")
    g.add_argument("out")
    g.add_argument("folder")
    p.set_defaults(func=_cmd_gait_camera)

    p = sub.add_parser("datasets", help="the public recordings of the registry (datasets/registry.toml)",
                       description="List the registered public recordings, or download them with their checksums "
                                   "verified. PDR_DATA_DIR points pdr at a local copy (default: ../shared/datasets "
                                   "beside the repository, else the download cache).")
    gsub = p.add_subparsers(dest="action", required=True)
    gsub.add_parser("list", help="each dataset: source, licence, ground truth, and whether its files are present")
    g = gsub.add_parser("path", help="print the local folder of a dataset (an error that says how to get it if absent)")
    g.add_argument("name", metavar="NAME")
    g = gsub.add_parser("fetch", help="download datasets into the cache (or --dir) and verify each sha256",
                        description="example: pdr datasets fetch humolire_phone_landmarks --dir data")
    g.add_argument("names", nargs="+", metavar="NAME")
    g.add_argument("--dir", default=None, help="destination folder (default: the download cache)")
    p.set_defaults(func=_cmd_datasets)
    return parser


def _format_warning(message, category, filename, lineno, line=None) -> str:
    return f"warning: {message}\n"


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    warnings.formatwarning = _format_warning
    try:
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


def entry_point() -> None:
    sys.exit(main())
