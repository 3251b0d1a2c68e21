"""A reference GMIKF kernel re-created from git, for A/B benchmarks in one process.

    from benchmarks.reference_kernel import load_reference_kernel
    ref = load_reference_kernel("b36893a")      # module with gmikf_chunk, EpochInputs, …
    tree = reference_tree("9f59828")            # a whole old tree, for a child's PYTHONPATH
    w = TreeWorker(script, tree, folder, log)   # a worker process of script on that tree

The kernel modules (gmis/gmikf.py and the numba modules it compiles in: dense,
measurement_models, system_model) are read with ``git show COMMIT:path`` into a package
``gmis_ref_<commit>`` under ~/.cache/gmis-bench (numba's cache=True then survives between
runs); their imports of each other are rewritten to that package, every other gmis import
(state, frames, gravity) stays the live one. Nothing is copied into the source tree, so
the reference adds no duplicate code; the benchmark needs the git history.
"""

import argparse
import importlib
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

TAG = "BENCH "          # prefix of a worker's protocol lines on stdout
KERNEL_MODULES = ("gmikf", "dense", "measurement_models", "system_model")
REPO = Path(__file__).resolve().parents[1]
CACHE = Path.home() / ".cache" / "gmis-bench"


def _git_show(commit: str, path: str) -> str | None:
    out = subprocess.run(["git", "-C", str(REPO), "show", f"{commit}:{path}"],
                         check=False, capture_output=True, text=True)
    return out.stdout if out.returncode == 0 else None


def reference_tree(commit: str) -> Path:
    """``git archive COMMIT gmis gnss vce`` unpacked under ~/.cache/gmis-bench/tree-<commit>
    (once; numba's cache then lives beside it): a whole old tree for PYTHONPATH."""
    full = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short=10", commit],
                          capture_output=True, text=True, check=True).stdout.strip()
    tree = CACHE / f"tree-{full}"
    if not (tree / "gmis").is_dir():
        tree.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(["git", "-C", str(REPO), "archive", full, "gmis", "gnss",
                                  "vce"], capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
    return tree


def load_reference_kernel(commit: str):
    """The reference gmis.gmikf module of ``commit`` (see the module doc)."""
    full = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short=10", commit],
                          capture_output=True, text=True, check=True).stdout.strip()
    package = f"gmis_ref_{full}"
    folder = CACHE / package
    folder.mkdir(parents=True, exist_ok=True)
    present = []
    for name in KERNEL_MODULES:
        text = _git_show(full, f"gmis/{name}.py")
        if text is not None:
            present.append(name)
            if not (folder / f"{name}.py").exists():
                (folder / f"{name}.py").write_text(text)
    pattern = re.compile(r"\bfrom gmis\.(" + "|".join(present) + r") import")
    for name in present:
        path = folder / f"{name}.py"
        text = path.read_text()
        new = pattern.sub(lambda m: f"from {package}.{m.group(1)} import", text)
        if new != text:
            path.write_text(new)
    (folder / "__init__.py").touch()
    if str(CACHE) not in sys.path:
        sys.path.insert(0, str(CACHE))
    return importlib.import_module(f"{package}.gmikf")


def say(**kw) -> None:
    """A worker's answer: one TAG line of JSON on stdout."""
    print(TAG + json.dumps(kw), flush=True)


class TreeWorker:
    """``python script --worker folder`` with PYTHONPATH at ``tree`` (this tree or a
    reference_tree), run from ``folder``; it answers TAG lines (``say``): first when it is
    ready, then one per command line sent by ``ask``. Its stderr goes to ``log``."""

    def __init__(self, script: Path, tree: Path, folder: Path, log: Path):
        env = dict(os.environ, PYTHONPATH=str(tree))
        self.log = open(log, "w")  # noqa: SIM115 (closed in close())
        self.proc = subprocess.Popen([sys.executable, str(script), "--worker", str(folder)],
                                     cwd=str(folder), env=env, stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=self.log, text=True)
        self.info = None                 # the worker's first line, once it is ready

    def reply(self) -> dict:
        for line in self.proc.stdout:
            if line.startswith(TAG):
                return json.loads(line[len(TAG):])
        raise SystemExit(f"worker failed, see {self.log.name}")

    def ask(self, line: str) -> dict:
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()
        return self.reply()

    def close(self):
        self.proc.stdin.write("quit\n")
        self.proc.stdin.close()
        self.proc.wait()
        self.log.close()


def ab_arguments(ap: argparse.ArgumentParser) -> None:
    """The A/B options of the worker-per-tree benchmarks: --reference, --rounds, --keep
    and the hidden --worker FOLDER of a worker process."""
    ap.add_argument("--reference", default="9f59828",
                    help="git commit of the reference tree ('none': this tree only)")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--keep", type=Path, help="simulate into / reuse this folder")
    ap.add_argument("--worker", type=Path, help=argparse.SUPPRESS)


def bench_folder(keep: Path | None, prefix: str) -> Path:
    """--keep, or a new temporary folder, created and absolute."""
    folder = (keep or Path(tempfile.mkdtemp(prefix=prefix))).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def start_workers(script: Path, reference: str, folder: Path, log_stem: str) -> dict:
    """{label: TreeWorker}: the reference tree first (unless reference is 'none'), then
    this tree; both start (read and prepare) side by side."""
    trees = {"this": REPO}
    if reference != "none":
        trees = {f"ref@{reference}": reference_tree(reference), **trees}
    return {label: TreeWorker(script, tree, folder, folder / f"{log_stem}-{i}.log")
            for i, (label, tree) in enumerate(trees.items())}


def parse_ab(ap: argparse.ArgumentParser, worker):
    """Parse the command line; in a worker process (--worker FOLDER) run worker(FOLDER) and
    return None, else put this tree first on sys.path (the main process's gmis) and return
    the arguments."""
    args = ap.parse_args()
    if args.worker:
        worker(args.worker)
        return None
    sys.path.insert(0, str(REPO))
    return args


def max_state_difference(x_this, x_ref) -> float:
    """Largest |x_this − x_ref| over all epochs and states, the heading wrapped to ±π
    (NaN when the shapes differ)."""
    import numpy as np

    from gmis.state import I_HEADING
    if x_this.shape != x_ref.shape:
        return float("nan")
    d = x_this - x_ref
    d[:, I_HEADING] = (d[:, I_HEADING] + np.pi) % (2.0 * np.pi) - np.pi   # ψ wraps
    return float(np.nanmax(np.abs(d)))
