"""`gmis batch SPEC.toml`: many gmis jobs on dask.distributed (issue 18).

A batch spec (docs/formats.md "Batch spec")::

    [batch]
    output = "batch-results"      # root folder; each job writes <output>/<job name>/
    workers = 2                   # LocalCluster worker processes (default 2)
    # scheduler = "tcp://host:8786"   # a running dask scheduler instead of a LocalCluster

    [[job]]
    command = "run"               # run | vce | outages | simulate
    recipes = ["a/recipe.toml", "b/recipe.toml"]   # or recipe = "...": one job each
    options = { output_rate_hz = 10.0 }

    [[job]]
    command = "simulate"          # Monte Carlo: simulate the scenario with each seed ...
    scenario = "default"
    seeds = [1, 2, 3, 4]
    then = "run"                  # ... and run (or vce) the simulated dataset

Every job is one call of :func:`run_job` in a worker process: its own folder, its own
exceptions. A failing job becomes one line in the table and on the terminal; the others
are kept. ``batch.csv`` (one row per job: name, command, status, CPU and wall time, key
figures, error) and ``batch.json`` gather the results. The same function runs the jobs
in-process one after another with ``serial=True`` (the reference of the benchmark), so a
job's files do not depend on where it ran.

Python API::

    rows = run_batch("spec.toml")                    # LocalCluster
    rows = run_batch("spec.toml", scheduler="tcp://...")
    rows = run_batch(jobs=expand_jobs(spec), output="out", serial=True)
"""

from __future__ import annotations

import csv
import json
import math
import sys
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from gmis.errors import GmisInputError

COMMANDS = ("run", "vce", "outages", "simulate")
THEN = ("run", "vce")
DEFAULT_WORKERS = 2


@dataclass
class Job:
    """One unit of work: a command on a recipe (or a scenario and seed), its options."""
    name: str
    command: str
    recipe: str | None = None
    scenario: str | None = None
    seed: int | None = None
    then: str | None = None
    options: dict = field(default_factory=dict)


def _job_error(spec_path, i, key, problem):
    return GmisInputError(f"job[{i}].{key}: {problem}", source=str(spec_path))


def _resolve(base: Path, value: str) -> str:
    if value == "default":
        return value
    p = Path(value)
    return str(p if p.is_absolute() else (base / p).resolve())


def expand_jobs(spec: dict, spec_path="batch spec") -> list[Job]:
    """The spec's [[job]] tables expanded over their recipes and seeds, with unique names
    (<command>-<recipe folder>[-seed<k>], or the table's ``name`` as prefix)."""
    base = Path(spec_path).resolve().parent if spec_path != "batch spec" else Path.cwd()
    tables = spec.get("job")
    if not isinstance(tables, list) or not tables:
        raise GmisInputError("job: at least one [[job]] table is required",
                             source=str(spec_path))
    jobs: list[Job] = []
    known = {"command", "recipe", "recipes", "scenario", "seeds", "seed", "then", "options",
             "name"}
    for i, t in enumerate(tables):
        unknown = sorted(set(t) - known)
        if unknown:
            raise _job_error(spec_path, i, unknown[0], f"unknown key (known: {sorted(known)})")
        command = t.get("command")
        if command not in COMMANDS:
            raise _job_error(spec_path, i, "command", f"must be one of {COMMANDS}, got "
                             f"{command!r}")
        options = t.get("options", {})
        if not isinstance(options, dict):
            raise _job_error(spec_path, i, "options", "must be a table")
        _check_options(spec_path, i, t.get("then") if command == "simulate" else command,
                       options)
        seeds = t.get("seeds", [t["seed"]] if "seed" in t else [None])
        if not isinstance(seeds, list) or not all(s is None or isinstance(s, int)
                                                  for s in seeds):
            raise _job_error(spec_path, i, "seeds", "must be a list of integers")
        if command == "simulate":
            if not isinstance(t.get("scenario"), str):
                raise _job_error(spec_path, i, "scenario", "required (a scenario file or "
                                 "an embedded scenario name)")
            then = t.get("then")
            if then is not None and then not in THEN:
                raise _job_error(spec_path, i, "then", f"must be one of {THEN}, got {then!r}")
            scenario = t["scenario"]
            if (base / scenario).exists():
                scenario = str((base / scenario).resolve())
            stem = Path(scenario).stem
            for s in seeds:
                jobs.append(Job(f"{t.get('name', f'simulate-{stem}')}"
                                + (f"-seed{s}" if s is not None else ""), command,
                                scenario=scenario, seed=s, then=then, options=dict(options)))
            continue
        recipes = t.get("recipes", [t["recipe"]] if "recipe" in t else None)
        if not isinstance(recipes, list) or not recipes or \
                not all(isinstance(r, str) for r in recipes):
            raise _job_error(spec_path, i, "recipes", "required: recipe = \"...\" or "
                             "recipes = [...]")
        for r in recipes:
            path = _resolve(base, r)
            label = "default" if r == "default" else Path(path).parent.name
            jobs.append(Job(f"{t.get('name', command)}-{label}", command, recipe=path,
                            options=dict(options)))
    seen: dict[str, int] = {}
    for job in jobs:                     # unique folder names
        k = seen.get(job.name, 0)
        seen[job.name] = k + 1
        if k:
            job.name = f"{job.name}-{k + 1}"
    return jobs


def load_spec(path) -> tuple[dict, list[Job]]:
    """(the [batch] table, the expanded jobs) of a batch spec file."""
    path = Path(path)
    try:
        spec = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise GmisInputError(f"not valid TOML ({exc})", source=str(path)) from None
    batch = spec.get("batch", {})
    unknown = sorted(set(batch) - {"output", "workers", "scheduler"})
    if unknown:
        raise GmisInputError(f"batch.{unknown[0]}: unknown key (known: output, workers, "
                             "scheduler)", source=str(path))
    workers = batch.get("workers", DEFAULT_WORKERS)
    if not isinstance(workers, int) or workers < 1:
        raise GmisInputError(f"batch.workers: must be an integer >= 1, got {workers!r}",
                             source=str(path))
    return batch, expand_jobs(spec, path)


def _figures(summary: dict, command: str) -> dict:
    """A few key figures of a job's summary for the batch table."""
    out = {}
    if command == "run":
        err = summary.get("errors_vs_reference", {})
        pos = err.get("position", {})
        if pos:
            out["h_rms_m"] = math.hypot(pos["e"]["rms"], pos["n"]["rms"])
            out["u_rms_m"] = pos["u"]["rms"]
        att = err.get("attitude", {})
        if att:
            out["heading_rms_deg"] = att["heading"]["rms"]
        out["epochs"] = summary.get("epochs")
    elif command == "vce":
        out["iterations"] = summary.get("iterations")
        out["converged"] = summary.get("converged")
    elif command == "outages":
        out["windows"] = len(summary.get("windows", []))
    return out


def _execute(job: Job, folder: Path) -> dict:
    """Run one job into folder; returns its summary figures."""
    from contextlib import redirect_stdout
    from io import StringIO

    with redirect_stdout(StringIO()):       # the engines' one-line notices
        if job.command == "simulate":
            from gmis.simulate import scenario_path as named
            from gmis.simulate import simulate_scenario
            scenario = job.scenario if Path(job.scenario).exists() else named(job.scenario)
            dataset = folder / "dataset" if job.then else folder
            sim = simulate_scenario(scenario, dataset, seed=job.seed, overwrite=True)
            if job.then is None:
                return {"recipe": str(sim.recipe_path)}
            sub = Job(job.name, job.then, recipe=str(sim.recipe_path), options=job.options)
            figures = _execute(sub, folder / job.then)
            return {"then": job.then, **figures}
        recipe = job.recipe
        if recipe == "default":
            from gmis.simulate import default_scenario_path, simulate_scenario
            recipe = str(simulate_scenario(default_scenario_path(), folder / "dataset",
                                           seed=None, overwrite=True).recipe_path)
            folder = folder / job.command
        opts = dict(job.options)
        if job.command == "run":
            from gmis.pipeline import run_recipe
            rate = opts.pop("output_rate_hz", 10.0)
            summary = run_recipe(recipe, folder, csv_rate_hz=rate if rate > 0 else math.inf,
                                 **opts)
        elif job.command == "vce":
            from vce.job import tune_recipe
            summary = tune_recipe(recipe, folder, **opts)
            if summary.get("refused"):
                raise GmisInputError(summary["refused"])
        else:
            from gmis.outages import run_outage_experiment
            summary = run_outage_experiment(recipe, results_dir=folder, **opts)
    return _figures(summary, job.command)


def _number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _windows(v):
    return isinstance(v, list) and all(isinstance(w, list) and len(w) == 2
                                       and all(_number(x) for x in w) for w in v)


# the engine keyword arguments a job may set (docs/formats.md "Batch spec"), each with a
# check and what it expects
OPTIONS = {
    "run": {"output_rate_hz": (lambda v: _number(v) and v >= 0, "a number >= 0 (Hz)"),
            "gnss_outages": (_windows, "a list of [start_gps_s, end_gps_s] pairs"),
            "smooth": (lambda v: isinstance(v, bool), "true or false")},
    "vce": {"max_iterations": (lambda v: isinstance(v, int) and not isinstance(v, bool)
                               and v >= 1, "an integer >= 1"),
            "tol": (lambda v: _number(v) and v > 0, "a number > 0"),
            "min_redundancy": (lambda v: _number(v) and 0 <= v < 1, "a number in [0, 1)"),
            "estimate_drifts": (lambda v: isinstance(v, bool), "true or false")},
    "outages": {"duration_s": (lambda v: _number(v) and v > 0, "a number > 0 (s)"),
                "count": (lambda v: isinstance(v, int) and not isinstance(v, bool)
                          and v >= 1, "an integer >= 1"),
                "keep_heading": (lambda v: isinstance(v, bool), "true or false"),
                "dr_biases": (lambda v: v in ("raw", "filter"), "\"raw\" or \"filter\"")},
}


def _check_options(spec_path, i, command, options) -> None:
    """One line for an option the job's engine does not take or a value of the wrong type,
    before any job runs (a TypeError inside the job, before)."""
    allowed = OPTIONS.get(command, {})
    for key, value in options.items():
        if key not in allowed:
            raise _job_error(spec_path, i, f"options.{key}", "unknown option for "
                             f"{command or 'simulate'} (known: {sorted(allowed)})")
        check, expected = allowed[key]
        if not check(value):
            raise _job_error(spec_path, i, f"options.{key}", f"expected {expected}, got "
                             f"{value!r}")


def run_job(job: Job, root: str) -> dict:
    """One job in its own folder <root>/<name>; never raises: a failure is a row with
    status "failed" and the one-line error."""
    c0, w0 = time.process_time(), time.perf_counter()
    row = {"name": job.name, "command": job.command, "recipe": job.recipe or job.scenario,
           "seed": job.seed, "folder": str(Path(root) / job.name)}
    folder = Path(root) / job.name
    earlier = folder.is_dir() and any(folder.iterdir())   # an earlier batch's results
    try:
        figures = _execute(job, folder)
        row.update(status="ok", error="", **figures)
    except Exception as exc:            # noqa: BLE001 - reported, the batch goes on
        error = " ".join(f"{type(exc).__name__}: {exc}".split())
        if earlier:                     # never deleted, but not this run's either
            error += f" (the folder {folder.name} still holds an earlier batch's results)"
        row.update(status="failed", error=error)
    finally:
        from gmis import output_folder
        output_folder.mark(folder, "batch")     # a re-run may replace what gmis wrote
    row.update(cpu_s=time.process_time() - c0, wall_s=time.perf_counter() - w0)
    return row


def _say(quiet, text):
    if not quiet:
        print(text, file=sys.stderr, flush=True)


def _progress_line(done, total, row):
    status = row["status"] if row["status"] == "ok" else f"FAILED: {row['error']}"
    return (f"gmis batch: [{done}/{total}] {row['name']}: {status} "
            f"({row['wall_s']:.1f} s wall, {row['cpu_s']:.1f} s CPU)")


def check_batch_folders(root: Path, jobs, spec_path=None) -> None:
    """Refuse, before any job runs, a root or job folder that gmis may not write
    (gmis.output_folder: not empty and without the gmis marker, the current directory, a
    folder that holds the spec or a recipe's files): a job replaces its folder <root>/<name>,
    so a user's folder of the same name must never be there."""
    from gmis import output_folder

    inputs = [Path(spec_path)] if spec_path is not None else []
    for job in jobs:
        if job.recipe and job.recipe != "default":
            inputs += output_folder.recipe_inputs(job.recipe)
        if job.scenario and Path(job.scenario).exists():
            inputs.append(Path(job.scenario))
    output_folder.check_output_folder(root, "batch", inputs)
    for job in jobs:
        output_folder.check_output_folder(root / job.name, "batch")


def run_batch(spec_path=None, output=None, workers: int | None = None,
              scheduler: str | None = None, serial: bool = False, jobs=None,
              quiet: bool = False) -> list[dict]:
    """Run every job of a spec (or the given jobs) and write <output>/batch.csv and
    batch.json; returns the rows in job order. serial=True runs them in this process one
    after another; otherwise on dask.distributed (a LocalCluster of ``workers`` processes,
    one thread each, or the scheduler at ``scheduler``)."""
    batch = {}
    if spec_path is not None:
        batch, spec_jobs = load_spec(spec_path)
        jobs = spec_jobs if jobs is None else jobs
    if not jobs:
        raise GmisInputError("no jobs to run", source=str(spec_path or "batch"))
    root = Path(output or batch.get("output", "batch-results")).resolve()
    check_batch_folders(root, jobs, spec_path)
    root.mkdir(parents=True, exist_ok=True)
    from gmis import output_folder
    output_folder.mark(root, "batch")
    workers = workers or batch.get("workers", DEFAULT_WORKERS)
    scheduler = scheduler or batch.get("scheduler")
    rows: dict[str, dict] = {}
    w0 = time.perf_counter()
    if serial:
        for k, job in enumerate(jobs, 1):
            rows[job.name] = run_job(job, str(root))
            _say(quiet, _progress_line(k, len(jobs), rows[job.name]))
    else:
        rows = _run_distributed(jobs, root, workers, scheduler, quiet)
    ordered = [rows[j.name] for j in jobs]
    _write_table(root, ordered, time.perf_counter() - w0)
    output_folder.mark(root, "batch")        # now listing batch.csv / batch.json too
    return ordered


def _run_distributed(jobs, root: Path, workers: int, scheduler, quiet) -> dict:
    try:
        from distributed import Client, LocalCluster, as_completed
    except ModuleNotFoundError:
        raise GmisInputError("dask.distributed is not installed (pip install "
                             "'gmis[dist]'); or run with --serial", source="gmis batch") \
            from None
    import logging
    # dask's own records (worker start/stop, "Lost all workers" at shutdown) are not the
    # user's business: the jobs' rows say what happened
    logging.getLogger("distributed").setLevel(logging.ERROR)
    cluster = None
    if scheduler is None:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=logging.ERROR)
    rows = {}
    try:
        with Client(cluster if cluster is not None else scheduler) as client:
            futures = {client.submit(run_job, job, str(root), key=f"gmis-{job.name}",
                                     pure=False): job for job in jobs}
            for done, fut in enumerate(as_completed(futures), 1):
                job = futures[fut]
                try:
                    row = fut.result()
                except Exception as exc:   # noqa: BLE001 - the worker died: one line
                    row = {"name": job.name, "command": job.command, "status": "failed",
                           "error": " ".join(f"{type(exc).__name__}: {exc}".split()),
                           "cpu_s": math.nan, "wall_s": math.nan}
                rows[job.name] = row
                _say(quiet, _progress_line(done, len(jobs), row))
    finally:
        if cluster is not None:
            cluster.close()
    return rows


def _write_table(root: Path, rows: list[dict], wall_s: float):
    keys = []
    for row in rows:
        keys += [k for k in row if k not in keys]
    with open(root / "batch.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys, restval="")
        w.writeheader()
        w.writerows(rows)
    (root / "batch.json").write_text(json.dumps(
        {"jobs": rows, "wall_s": wall_s, "failed": sum(r["status"] != "ok" for r in rows)},
        indent=2, default=str, allow_nan=True) + "\n")


__all__ = ["Job", "expand_jobs", "load_spec", "run_batch", "run_job"]
