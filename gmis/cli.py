"""The ``gmis`` command line: simulate, run, vce, report, rtk, outages.

Bad input (GmisInputError, or a user path that cannot be opened) prints one line
``gmis: error: <message>`` on stderr and exits with status 2 — no traceback. A command
whose engine module is not in this version exits with status 3.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import math
import re
import sys
import textwrap
from pathlib import Path

from gmis import __version__
from gmis.errors import GmisInputError
from gnss.errors import GnssInputError

EXIT_INPUT_ERROR = 2
EXIT_NOT_AVAILABLE = 3
EXIT_MISSING_DEPENDENCY = 4
DEFAULT_WORKDIR = Path("gmis-default")

DESCRIPTION = """\
gmis — post-processing for land-vehicle road tests: IMU + GNSS + dual-antenna heading in a
total-state kinematic Kalman filter (GMIKF, Qian 2017), with Helmert variance component
estimation (VCE) to tune the noise model.

Units: recipes and reports use degrees, metres, seconds (GPS time); everything inside is
SI and radians. Navigation frame: local ENU; body frame: Right-Forward-Up; Euler angles
[pitch, roll, heading], heading an azimuth clockwise from north.
The dataset recipe (TOML) format is described in docs/formats.md.
"""

RECIPE_HELP = ("dataset recipe (TOML, see docs/formats.md), or the word 'default' for the "
               "embedded default dataset (simulated into ./gmis-default/dataset on first use)")
RTK_RECIPE_HELP = "GNSS recipe (TOML with [paths] rover_obs, base_obs, nav and [base])"


class _NotAvailable(Exception):
    pass


def _import(module: str, command: str):
    """Import ``module``; if it (or a parent package) does not exist in this version,
    raise _NotAvailable. A missing dependency *inside* the module is re-raised."""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        parts = module.split(".")
        own_names = {".".join(parts[: i + 1]) for i in range(len(parts))}
        if exc.name in own_names:
            raise _NotAvailable(command) from None
        raise


def _progress(args, label: str):
    from gmis.progress import Progress

    return Progress(1.0, label, quiet=getattr(args, "quiet", False))


def _say(args, message: str) -> None:
    if not getattr(args, "quiet", False):
        print(message)


def _find_recipe(dataset_dir: Path) -> Path | None:
    preferred = dataset_dir / "recipe.toml"
    if preferred.is_file():
        return preferred
    candidates = sorted(dataset_dir.glob("*.toml"))
    return candidates[0] if len(candidates) == 1 else None


def _default_recipe(args) -> Path:
    """Simulate the embedded default scenario once into ./gmis-default/dataset; reuse it."""
    dataset_dir = DEFAULT_WORKDIR / "dataset"
    if dataset_dir.exists():
        recipe = _find_recipe(dataset_dir)
        if recipe is None:
            raise GmisInputError("no recipe (*.toml) in the default dataset folder; delete "
                                 "the folder to simulate it again", source=str(dataset_dir))
        _say(args, f"gmis: reusing the default dataset in {dataset_dir}")
        return recipe
    simulate = _import("gmis.simulate", "run default")
    _say(args, f"gmis: simulating the default dataset into {dataset_dir} (first use only)")
    with _progress(args, "simulate") as progress:
        result = simulate.simulate_scenario(simulate.default_scenario_path(), dataset_dir,
                                            seed=None, progress=progress)
    return Path(result.recipe_path)


def _resolve_recipe(args, command: str) -> tuple[Path, Path]:
    """(recipe path, results dir) from ``args.recipe`` and ``args.output``; validates the
    recipe before any engine module is imported, so input errors come first."""
    from gmis import output_folder
    from gmis.recipe import load_recipe

    if args.recipe == "default":
        if command == "rtk":
            raise GmisInputError("the embedded default dataset has no RINEX observations; "
                                 "give a recipe with [paths] rover_obs, base_obs, nav",
                                 source="rtk default")
        default_out = DEFAULT_WORKDIR / ("results" if command == "run" else command)
        output_folder.check_output_folder(args.output or default_out, command)
        recipe_path = _default_recipe(args)
    else:
        recipe_path = Path(args.recipe)
        default_out = Path(f"{command}-{recipe_path.resolve().parent.name or 'results'}")
        if command == "run":
            default_out = Path(f"results-{recipe_path.resolve().parent.name or 'dataset'}")
    if command == "rtk":
        # the same loader, GNSS-only: no IMU needed, [paths] RINEX and [base] required
        _import("gmis.rtk_job", "rtk").read_rtk_recipe(recipe_path)
    else:
        load_recipe(recipe_path)
    results_dir = Path(args.output) if args.output is not None else default_out
    output_folder.check_and_claim(results_dir, command, output_folder.recipe_inputs(recipe_path))
    return recipe_path, results_dir


_SUMMARY_PRIORITY = ("error", "rms", "converge", "iteration", "fix")
_SUMMARY_MAX_LINES = 40


def _format_scalar(value, name: str = "") -> str | None:
    if hasattr(value, "item") and getattr(value, "ndim", 1) == 0:
        value = value.item()
    if isinstance(value, (bool, int)):
        return str(value)
    if isinstance(value, float) and name.endswith("heading_deg"):
        return f"{round(value, 2) % 360.0:.2f}"   # 359.997 is 0.00, not "360"
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, str):
        return value if len(value) <= 100 else None
    if isinstance(value, (list, tuple)) and 0 < len(value) <= 6 and all(
            isinstance(x, (int, float)) and not isinstance(x, bool) for x in value):
        return "[" + ", ".join(f"{x:.4g}" for x in value) + "]"
    return None


def summary_lines(summary) -> list[str]:
    """Key figures of an engine's summary dict, one ``name: value`` line each: nested
    dicts get dotted names, a small dict of scalars is folded onto one line (its ``unit``
    entry last), arrays and long lists are left out; error/RMS/convergence figures first."""
    entries: list[tuple[str, str]] = []

    def walk(name: str, value) -> None:
        if isinstance(value, dict):
            scalars = {k: _format_scalar(v, k) for k, v in value.items()}
            if value and all(v is not None for v in scalars.values()):
                unit = scalars.pop("unit", "")
                text = ", ".join(f"{k} {v}" for k, v in scalars.items()) + (
                    f" {unit}" if unit else "")
                if len(text) <= 140 and name:
                    entries.append((name, text))
                    return
            for key, item in value.items():
                walk(f"{name}.{key}" if name else str(key), item)
            return
        text = _format_scalar(value, name)
        if text is not None:
            entries.append((name, text))

    if isinstance(summary, dict):
        walk("", summary)
    elif summary is not None:
        return [f"  {summary}"]
    def secondary(entry) -> bool:
        words = re.split(r"[._]", entry[0].lower())
        return not any(w.startswith(p) for w in words for p in _SUMMARY_PRIORITY)

    ranked = sorted(entries, key=secondary)
    lines = [f"  {name}: {text}" for name, text in ranked[:_SUMMARY_MAX_LINES]]
    if len(ranked) > _SUMMARY_MAX_LINES:
        lines.append(f"  ... {len(ranked) - _SUMMARY_MAX_LINES} more figures in the results "
                     "folder")
    return lines


def _print_summary(summary) -> None:
    for line in summary_lines(summary):
        print(line)


# ----------------------------------------------------------------------------- commands


def cmd_simulate(args) -> int:
    from gmis.recipe import read_toml

    scenario = Path(args.scenario)
    if not scenario.exists() and scenario.suffix == "" and scenario.name == args.scenario:
        embedded = Path(_import("gmis.simulate", "simulate").scenario_path(args.scenario))
        if embedded.is_file():
            scenario = embedded
    read_toml(scenario)  # existence and TOML syntax, before the simulator is imported
    out_dir = Path(args.output) if args.output else Path(f"dataset-{scenario.stem}")
    from gmis import output_folder
    output_folder.check_output_folder(out_dir, "simulate", [scenario], args.overwrite)
    simulate = _import("gmis.simulate", "simulate")
    extra = {"overwrite": True} if args.overwrite else {}
    with _progress(args, "simulate") as progress:
        result = simulate.simulate_scenario(scenario, out_dir, seed=args.seed,
                                            progress=progress, **extra)
    output_folder.mark(result.dataset_dir, "simulate")
    print(f"gmis simulate: dataset written to {result.dataset_dir}")
    print(f"  recipe: {result.recipe_path}")
    print(f"  next:   gmis run {result.recipe_path}")
    return 0


def _run_engine(args, label: str, done: str, engine, *engine_args, **options) -> int:
    """Run one engine with a progress line, then print ``done`` and its key figures."""
    with _progress(args, label) as progress:
        summary = engine(*engine_args, progress=progress, **options)
    print(done)
    _print_summary(summary)
    return 0


def cmd_run(args) -> int:
    recipe_path, results_dir = _resolve_recipe(args, "run")
    from gmis.outage_windows import parse_window_spec

    windows = [parse_window_spec(w, "--gnss-outage") for w in args.gnss_outage]
    if not (args.output_rate >= 0 and math.isfinite(args.output_rate)):
        raise GmisInputError(f"must be a rate >= 0 Hz (0 = every epoch), got "
                             f"{args.output_rate}", "--output-rate")
    pipeline = _import("gmis.pipeline", "run")
    return _run_engine(args, "GMIKF", f"gmis run: results written to {results_dir}",
                       pipeline.run_recipe, recipe_path, results_dir, gnss_outages=windows,
                       csv_rate_hz=args.output_rate if args.output_rate > 0 else math.inf,
                       **({"smooth": True} if args.smooth else {}))


def cmd_vce(args) -> int:
    recipe_path, results_dir = _resolve_recipe(args, "vce")
    from vce.job import tune_recipe

    if not 1 <= args.max_iterations <= 100:
        raise GmisInputError(f"must be 1..100, got {args.max_iterations}", "--max-iterations")
    if not 0.0 < args.tol < 1.0:
        raise GmisInputError(f"must be in (0, 1), got {args.tol}", "--tol")
    if not 0.0 <= args.min_redundancy < 1.0:
        raise GmisInputError(f"must be in [0, 1), got {args.min_redundancy}",
                             "--min-redundancy")
    with _progress(args, "VCE") as progress:
        summary = tune_recipe(recipe_path, results_dir, progress=progress,
                              max_iterations=args.max_iterations, tol=args.tol,
                              min_redundancy=args.min_redundancy,
                              estimate_drifts=args.estimate_drifts)
    if summary.get("refused"):
        print(f"gmis: error: {_one_line(summary['refused'])}", file=sys.stderr)
        return EXIT_INPUT_ERROR
    print(f"gmis vce: tuning results written to {results_dir}")
    _print_summary(summary)
    return 0


def cmd_report(args) -> int:
    results_dir = Path(args.results)
    if not results_dir.is_dir():
        raise GmisInputError("results folder not found (run `gmis run` or `gmis vce` first)",
                             source=str(results_dir))
    from gmis import output_folder
    inputs = [results_dir] + ([Path(args.vce)] if args.vce else [])
    output_folder.check_and_claim(args.output or results_dir / "report", "report", inputs)
    report = _import("gmis.report", "report")
    formats = ("png",) + (("pdf",) if args.pdf else ()) + (("svg",) if args.svg else ())
    summary = report.make_report(results_dir, formats=formats, out_dir=args.output,
                                 vce_dir=args.vce)
    print(f"gmis report: report written for {results_dir}")
    _print_summary(summary)
    return 0


def cmd_outages(args) -> int:
    recipe_path, results_dir = _resolve_recipe(args, "outages")
    if args.window:
        from gmis.outage_windows import parse_window_spec

        windows = [parse_window_spec(w, "--window") for w in args.window]
        study = _import("gmis.outage_study", "outages --window")
        return _run_engine(args, "outages", f"gmis outages: results written to {results_dir}",
                           study.run_window_study, recipe_path, windows,
                           results_dir=results_dir, keep_heading=args.keep_heading,
                           smooth=args.smooth)
    if args.smooth:
        raise GmisInputError("--smooth: applies with --window START:DURATION (outages at "
                             "given times, scored against the withheld GNSS)")
    outages = _import("gmis.outages", "outages")
    return _run_engine(args, "outages", f"gmis outages: results written to {results_dir}",
                       outages.run_outage_experiment, recipe_path, duration_s=args.duration,
                       count=args.count, results_dir=results_dir,
                       keep_heading=args.keep_heading, dr_biases=args.dr_biases)


def cmd_batch(args) -> int:
    batch = _import("gmis.batch", "batch")
    if args.workers is not None and args.workers < 1:
        raise GmisInputError(f"must be >= 1, got {args.workers}", "--workers")
    rows = batch.run_batch(args.spec, output=args.output, workers=args.workers,
                           scheduler=args.scheduler, serial=args.serial, quiet=args.quiet)
    failed = [r for r in rows if r["status"] != "ok"]
    print(f"gmis batch: {len(rows) - len(failed)} of {len(rows)} jobs ok; table in "
          f"{Path(rows[0]['folder']).parent / 'batch.csv'}")
    for r in failed:
        print(f"gmis batch: {r['name']} failed: {r['error']}", file=sys.stderr)
    return 1 if failed else 0


def cmd_rtk(args) -> int:
    recipe_path, results_dir = _resolve_recipe(args, "rtk")
    if args.tight:
        tc = _import("gmis.tc_gnss_only", "rtk --tight")
        return _run_engine(args, "TC (no IMU)",
                           f"gmis rtk --tight: tightly coupled GMIKF solution WITHOUT IMU "
                           f"(kinematic model + DD updates) written to {results_dir}",
                           tc.run_tight_gnss_recipe, recipe_path, results_dir)
    rtk = _import("gmis.rtk_job", "rtk")
    return _run_engine(args, "RTK", f"gmis rtk: RTK solution written to {results_dir}",
                       rtk.run_rtk_recipe, recipe_path, results_dir)


def cmd_calibrate(args) -> int:
    from gmis import output_folder

    out_dir = Path(args.output or "calibration")
    output_folder.check_and_claim(out_dir, "calibrate", [Path(f) for f in args.files])
    job = _import("calibration.job", "calibrate")
    with _progress(args, "calibrate") as progress:
        summary = job.calibrate(args.files, out_dir, largest=args.model,
                                robust=args.robust, trim=args.trim,
                                imu_rate_hz=args.imu_rate, rate_hz=args.rate,
                                select=not args.no_select, datasheet=args.datasheet,
                                vce=args.vce, despike=args.despike,
                                horizon_s=args.horizon, min_scale_s=args.min_scale,
                                auto_scale=not args.all_scales, progress=progress)
    print(f"gmis calibrate: calibration written to {out_dir}")
    _print_summary(summary)
    return 0


# ----------------------------------------------------------------------------- parser


def _wrap(text: str) -> str:
    """Wrap each paragraph of a help text (RawDescriptionHelpFormatter keeps line breaks)."""
    return "\n".join(textwrap.fill(par, 88) if par else "" for par in text.split("\n"))


def _command(sub, name: str, summary: str, description: str, handler, *, recipe=True,
             output_help: str | None = None, quiet=True, recipe_help: str = RECIPE_HELP):
    """One sub-command: its parser (wrapped description), the recipe argument; ``finish``
    adds -o/--output and --quiet after the command's own options."""
    p = sub.add_parser(name, formatter_class=argparse.RawDescriptionHelpFormatter,
                       help=summary, description=_wrap(description))
    if recipe:
        p.add_argument("recipe", help=recipe_help)
    p.set_defaults(handler=handler)

    def finish():
        if output_help is not None:
            p.add_argument("-o", "--output", metavar="RESULTS", help=output_help)
        if quiet:
            p.add_argument("--quiet", action="store_true", help="no progress line")
        return p

    return p, finish


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="gmis", description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Exit status: 0 ok, 2 bad input (one-line message), 3 command not available "
               "in this version.")
    parser.add_argument("--version", action="version", version=f"gmis {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p, finish = _command(
        sub, "simulate", "simulate a dataset from a scenario file",
        "Simulate a road test from a scenario (TOML): true trajectory, IMU "
        "(rad/s, m/s² with the scenario's IMU errors), GNSS position/velocity "
        "solution (m, m/s), dual-antenna heading (deg), reference trajectory.\n"
        "Writes a dataset folder: the CSV files plus a recipe.toml that "
        "`gmis run` accepts.", cmd_simulate, recipe=False)
    p.add_argument("scenario", help="scenario file (TOML), or the name of an embedded "
                   "scenario: default, random_dynamics, tactical, tightly_coupled")
    p.add_argument("-o", "--output", metavar="OUTDIR",
                   help="dataset folder to write (default: ./dataset-<scenario file stem>)")
    p.add_argument("--seed", type=int, default=None,
                   help="random seed of every random stream: sensor noise, drawn biases, "
                   "random dynamics, raw GNSS (default: the scenario's seed)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace OUTDIR if it holds a dataset written by gmis (never another folder)")
    finish()

    p, finish = _command(
        sub, "run", "run the GMIKF on a dataset",
        "Run the GMIKF (total-state kinematic Kalman filter, 001 ch. 5) on a "
        "dataset recipe.\nWrites to the results folder (all-or-nothing): the "
        "navigation solution (position lat/lon deg, h m; ENU m; velocity m/s; "
        "attitude deg; sensor biases), 1σ of every state, innovations and "
        "residuals per sensor, and a summary (JSON) with the error against the "
        "reference when the dataset has one.", cmd_run,
        output_help="results folder (default: ./results-<dataset folder>; for "
                    "'default': ./gmis-default/results); an earlier gmis results "
                    "folder there is replaced, any other non-empty folder refused")
    p.add_argument("--gnss-outage", action="append", default=[], metavar="START:DURATION",
                   help="withhold GNSS position/velocity (and heading, see the recipe's "
                        "[outages].remove_heading) from START (GPS seconds of week) for "
                        "DURATION s; repeatable; added to the recipe's [outages].windows")
    p.add_argument("--output-rate", type=float, default=10.0, metavar="HZ",
                   help="rate of solution.csv / solution.pos in Hz, at most (every k-th "
                        "IMU epoch: 40 of 100 Hz gives 33.3; default 10; 0 = every epoch, "
                        "i.e. the full IMU rate; with --smooth at most the smoother's rate, "
                        "[filter].smoother_rate_hz); solution.npz always holds every epoch")
    p.add_argument("--smooth", action="store_true",
                   help="two-filter fixed-interval smoother ([filter].smoother = "
                        "\"two_filter\"): solution.* smoothed, solution_forward.* forward")
    finish()

    p, finish = _command(
        sub, "vce", "tune the noise model by iterative VCE",
        "Iterative Helmert variance component estimation in the Kalman filter "
        "(001 §2.7.2, ch. 5): re-estimates the process and measurement noise "
        "sigmas per sensor and axis until the variance factors converge.\n"
        "Writes to the results folder: every iteration's variance factors and "
        "redundancy, the tuned sigmas as a [noise] TOML fragment "
        "(use it with [paths].noise_override), the standardized residuals of the "
        "first and "
        "final iteration and sliding-window variance factors (for gmis report).", cmd_vce,
        output_help="results folder (default: ./vce-<dataset folder>)")
    p.add_argument("--max-iterations", type=int, default=30, metavar="N",
                   help="stop after N filter runs (default 30)")
    p.add_argument("--tol", type=float, default=0.02,
                   help="converged when |σ̂²₀ − 1| < TOL for every estimated component "
                        "(default 0.02)")
    p.add_argument("--min-redundancy", type=float, default=0.1, metavar="R",
                   help="components whose mean redundancy is below R keep their sigma "
                        "(001 §5.3; default 0.1; 0.001 lets the joint Helmert solution "
                        "estimate low-redundancy process noise, see docs/DESIGN.md)")
    p.add_argument("--estimate-drifts", action="store_true",
                   help="also estimate bias/scale-factor drift noises (redundancy ~1e-6)")
    finish()

    p, finish = _command(
        sub, "report", "make plots and tables from a results folder",
        "Make the report of a `gmis run` or `gmis vce` results folder: "
        "standardized-residual histograms against N(0,1), innovation and "
        "residual time series, VCE convergence, error against the reference "
        "(m, m/s, deg), tables in the shape of 001 Tables 6-3..6-7.\n"
        "Writes PNG figures, CSV tables and report.html into <results>/report.\n"
        "A folder holding run/ and vce/ sub-folders reports both.", cmd_report,
        recipe=False, quiet=False)  # its own -o (REPORT), no progress line
    p.add_argument("results", help="results folder written by `gmis run` or `gmis vce`")
    p.add_argument("--vce", metavar="VCE_RESULTS", help="also report this `gmis vce` folder")
    p.add_argument("-o", "--output", metavar="REPORT", help="report folder "
                   "(default: <results>/report)")
    p.add_argument("--pdf", action="store_true", help="also write figures as PDF")
    p.add_argument("--svg", action="store_true", help="also write figures as SVG")
    p.add_argument("--quiet", action="store_true",
                   help="accepted as by the other commands (report has no progress line)")

    p, finish = _command(
        sub, "rtk", "GNSS-only RTK (double differences + LAMBDA)",
        "GNSS-only kinematic RTK from the recipe's rover/base RINEX and "
        "broadcast navigation file: double differences, float solution, "
        "LAMBDA integer ambiguity resolution with the ratio test.\n"
        "Writes the rover positions (lat/lon deg, h m; ENU m), fix status, "
        "ratio and 1σ per epoch, and a summary (JSON).\n"
        "--tight runs the tightly coupled GMIKF instead, with the IMU ABSENT: the "
        "kinematic model propagates between GNSS epochs and DD code/L1/L2 rows "
        "update it, with in-filter ambiguity resolution (tc.pos, tc.csv, "
        "summary.json).", cmd_rtk,
        output_help="results folder (default: ./rtk-<dataset folder>)",
        recipe_help=RTK_RECIPE_HELP)
    p.add_argument("--tight", action="store_true",
                   help="tightly coupled GMIKF without IMU instead of gnss.rtk")
    finish()

    p, finish = _command(
        sub, "outages", "GNSS-outage drift: GMIKF vs conventional INS",
        "Simulated GNSS outages (001 §4.3.5, Table 4-7): removes GNSS "
        "position, velocity and heading in COUNT evenly spaced windows of "
        "DURATION s in the moving part of the run, runs the GMIKF and the "
        "conventional error-state INS/GNSS EKF on the same data, and pure dead "
        "reckoning of the IMU from each window start, and reports the "
        "maximum position drift per window (m, ENU and horizontal) and its RMS.\n"
        "Writes outages.csv, summary.json and outage_drift.png.", cmd_outages,
        output_help="results folder (default: ./outages-<dataset folder>)")
    p.add_argument("--duration", type=float, default=20.0, metavar="S",
                   help="length of each outage in seconds (default 20)")
    p.add_argument("--count", type=int, default=8, help="number of outages (default 8)")
    p.add_argument("--window", action="append", default=[], metavar="START:DURATION",
                   help="an outage at START (GPS seconds of week) for DURATION s instead of "
                        "the evenly spaced ones; repeatable (the recipe's [outages].windows "
                        "are added). Scored against the withheld GNSS solution at the "
                        "antenna; writes outage_windows.csv, summary.json, "
                        "outage_errors.png")
    p.add_argument("--keep-heading", action="store_true",
                   help="keep the dual-antenna heading inside the outages (default: removed "
                        "with GNSS position and velocity)")
    p.add_argument("--smooth", action="store_true",
                   help="with --window: score the GMIKF's two-filter smoother too (the "
                        "post-processed solution; columns gmikf_smoothed_*)")
    p.add_argument("--dr-biases", choices=("raw", "filter"), default="raw",
                   help="dead-reckoning baseline: raw IMU (default, 001 Table 4-7) or with "
                        "the error-state EKF's bias estimates removed")
    finish()

    p, finish = _command(
        sub, "batch", "many jobs (recipes, seeds, VCE, outages) on dask.distributed",
        "Run the jobs of a batch spec (TOML, docs/formats.md \"Batch spec\"): recipes × "
        "commands (run, vce, outages) and Monte Carlo seeds of a scenario (simulate, then "
        "run or vce), each in its own folder under the output folder, on a dask "
        "LocalCluster (or --scheduler). A failing job is reported in one line and the others "
        "are kept; batch.csv / batch.json gather one row per job. Exit status 1 when a job "
        "failed.", cmd_batch, recipe=False,
        output_help="root folder of the job folders (default: [batch].output or "
                    "./batch-results)")
    p.add_argument("spec", help="batch spec (TOML)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="LocalCluster worker processes (default [batch].workers or 2)")
    p.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="address of a running dask scheduler instead of a LocalCluster")
    p.add_argument("--serial", action="store_true",
                   help="run the jobs in this process one after another (no dask)")
    finish()

    p, finish = _command(
        sub, "calibrate", "stochastic IMU calibration (AV, GMWM, AWV)",
        "Stochastic calibration from static IMU records (CSV or gzip CSV, "
        "columns gyro_<axis>_<unit>, accel_<axis>_<unit>): Allan variance line "
        "fits, wavelet variance, GMWM model selection and fit; several files are "
        "replicates (AWV, AGMWM). Writes calibration.json, a [noise] recipe "
        "fragment, tables and figures (all-or-nothing).", cmd_calibrate,
        recipe=False, output_help="output folder (default ./calibration)")
    p.add_argument("files", nargs="+", metavar="FILE", help="static record(s)")
    p.add_argument("--model", default="WN+QN+3*AR1+RW",
                   help="largest model, e.g. WN+QN+2*AR1+RW+DR (default WN+QN+3*AR1+RW)")
    p.add_argument("--no-select", action="store_true",
                   help="fit the model as given instead of selecting among its nested models")
    p.add_argument("--robust", action="store_true", help="robust WV (RGMWM, SR/DR-AWV)")
    p.add_argument("--despike", action="store_true", help="replace isolated spikes (Hampel, "
                   "5 sigma) by their running median before the WV; with --robust the "
                   "RGMWM keeps its AR1/RW under additive outliers")
    p.add_argument("--trim", type=float, default=0.0, help="DR-AWV trim level in [0, 0.5)")
    p.add_argument("--imu-rate", type=float, default=None, metavar="HZ",
                   help="IMU rate of the recipe the fragment is for (default: the records')")
    p.add_argument("--rate", type=float, default=None, metavar="HZ",
                   help="sample rate when the files have no time_s column")
    p.add_argument("--datasheet", metavar="TOML", help="manufacturer values for the "
                   "comparison table (see docs/formats.md)")
    p.add_argument("--vce", metavar="TOML", help="tuned_noise.toml of `gmis vce` on a drive "
                   "with this sensor: the comparison table's VCE row (same IMU rate)")
    p.add_argument("--horizon", type=float, default=3600.0, metavar="S",
                   help="drive duration, s: a Gauss-Markov bias state over-bounds an "
                        "AR1+RW model on lags up to this (default 3600)")
    p.add_argument("--min-scale", type=float, default=None, metavar="S",
                   help="fit only the wavelet scales >= S seconds (drop the first scales "
                        "shaped by the sensor's own filter); default: chosen per axis by an "
                        "F test of the leading scales' misfit")
    p.add_argument("--all-scales", action="store_true",
                   help="fit every wavelet scale (no automatic smallest-scale choice)")
    finish()
    return parser


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from gmis.plausibility import one_line_warnings
    one_line_warnings()
    try:
        return args.handler(args)
    except GnssInputError as exc:      # GmisInputError is one
        print(f"gmis: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_INPUT_ERROR
    except OSError as exc:  # an unreadable input, a full or read-only disk, ...
        where = f": {exc.filename}" if exc.filename else ""
        if not exc.filename and exc.errno in (errno.ENOSPC, errno.EDQUOT):
            import tempfile
            where = (f" (the disk of the results folder or of gmis's temporary files in "
                     f"{tempfile.gettempdir()}; TMPDIR sets where those go)")
        print(f"gmis: error: {_one_line(exc.strerror or exc)}{where}", file=sys.stderr)
        return EXIT_INPUT_ERROR
    except _NotAvailable as exc:
        print(f"gmis {exc}: not yet available in this version", file=sys.stderr)
        return EXIT_NOT_AVAILABLE
    except ModuleNotFoundError as exc:  # an installation fault, not the user's data
        print(f"gmis: error: the Python package '{exc.name}' is not installed; install "
              "gmis with its dependencies (python3 -m pip install -e . in the source "
              "folder)", file=sys.stderr)
        return EXIT_MISSING_DEPENDENCY
    except KeyboardInterrupt:
        print("gmis: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
