"""Which folder a gmis command may write: checked before any work starts.

A command writes only into a folder that

* does not exist yet (its parents are created), or
* exists and is empty, or
* was written by gmis before: it holds the marker file :data:`MARKER`, which every
  folder written through :func:`gmis.results.results_directory` gets (the CLI's claimed
  folders with their command, the Python API's with "python") — or, for report and rtk,
  a main file that carries a gmis signature (SIGNATURES). ``gmis simulate`` replaces such
  a folder only with ``--overwrite``; the other commands replace their own earlier
  results, not another command's (the marker names it), and not a folder into which
  files were put that gmis did not write (the marker lists the files; gmis subfolders,
  e.g. a report, may be added). ``--overwrite`` never makes a folder without the marker
  writable.

Never the current directory (or one of its parents), a folder that holds an input of the
command (the recipe's folder, a data file's folder, the results folder being reported) or
a parent of one. A path that is a file, lies below a file, or is not writable (read-only
file system, /proc, no permission) is refused with one line naming the path — the
internal temporary ``.<name>.partial-<pid>`` folder is never shown.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

from gmis.errors import GmisInputError

MARKER = ".gmis-output"

_claims: dict[Path, str] = {}   # resolved output folder -> command that may write it


def _resolve(path) -> Path:
    return Path(os.path.abspath(os.path.expanduser(os.fspath(path))))


def _is_relative_to(path: Path, other: Path) -> bool:
    try:
        path.relative_to(other)
    except ValueError:
        return False
    return True


# Commands whose main output file says that gmis wrote it get no separate marker file
# (a report folder ships only files its report.html references; an RTK folder holds
# exactly its .pos, .csv and summary): the file carries this signature instead.
SIGNATURES = {"report.html": b'<meta name="generator" content="gmis report">',  # report/html.py
              "rtk.pos": b"% gmis rtk ",          # gnss.rtk.write_pos header of gmis rtk
              "tc.pos": b"% gmis rtk --tight "}   # ... and of gmis rtk --tight
SELF_SIGNED_COMMANDS = {"report", "rtk"}


SIGNED_BY = {"report.html": "report", "rtk.pos": "rtk", "tc.pos": "rtk"}


def signed_command(folder) -> str | None:
    """The command whose signed main file (SIGNATURES) the folder holds, or None."""
    for name, signature in SIGNATURES.items():
        try:
            with open(Path(folder) / name, "rb") as fh:
                head = fh.read(4096)
        except OSError:
            continue
        if (head.startswith(signature) if name.endswith(".pos") else signature in head):
            return SIGNED_BY[name]
    return None


def is_gmis_folder(folder) -> bool:
    """Written by gmis: holds the marker file, or a signed main file (SIGNATURES)."""
    return (Path(folder) / MARKER).is_file() or signed_command(folder) is not None


def recipe_inputs(recipe_path) -> list[Path]:
    """The recipe file and every file its [paths] table names (relative to the recipe),
    read leniently: the recipe's own validation reports problems, this only lists."""
    from gmis.recipe import read_toml

    recipe_path = _resolve(recipe_path)
    inputs = [recipe_path]
    try:
        doc = read_toml(recipe_path)
    except GmisInputError:
        return inputs
    paths = doc.get("paths", {}) if isinstance(doc, dict) else {}
    if isinstance(paths, dict):
        for value in paths.values():
            if isinstance(value, str) and value.strip():
                p = Path(os.path.expanduser(value))
                inputs.append(_resolve(p if p.is_absolute() else recipe_path.parent / p))
    return inputs


def _nearest_existing(path: Path) -> Path:
    p = path
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def _probe_writable(folder: Path, shown: str) -> None:
    """Create and remove a temporary folder in ``folder``: the only reliable test (root
    passes os.access on a read-only file system and on /proc)."""
    try:
        probe = tempfile.mkdtemp(prefix=".gmis-probe-", dir=folder)
        os.rmdir(probe)
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise GmisInputError(f"output folder cannot be created here ({reason} in {folder})",
                             source=shown) from None


def check_output_folder(path, command: str, inputs=(), overwrite: bool = False) -> Path:
    """Raise GmisInputError unless ``command`` may write its results into ``path``
    (see the module docstring); returns the resolved path. Call before any work."""
    shown = os.fspath(path)
    final = _resolve(path)
    cwd = _resolve(os.getcwd())
    if final == final.parent:
        raise GmisInputError("refusing to write into the file system root", source=shown)
    if _is_relative_to(cwd, final):
        raise GmisInputError("refusing to write into the current directory or one of its "
                             "parents; give a new folder name with -o", source=shown)
    for item in inputs:
        item = _resolve(item)
        folder = item if item.is_dir() else item.parent
        if _is_relative_to(folder, final):
            raise GmisInputError(f"refusing to write here: the folder holds the input "
                                 f"{item}; give a new folder name with -o", source=shown)
    existing = _nearest_existing(final)
    if existing != final and not existing.is_dir():
        raise GmisInputError(f"output path lies below the file {existing}", source=shown)
    if final.exists():
        if not final.is_dir():
            raise GmisInputError("output path exists and is not a folder", source=shown)
        try:
            entries = sorted(os.listdir(final))
        except OSError as exc:
            raise GmisInputError(f"output folder cannot be read ({exc.strerror})",
                                 source=shown) from None
        if entries and not is_gmis_folder(final):
            listed = ", ".join(entries[:3]) + (", ..." if len(entries) > 3 else "")
            raise GmisInputError(f"output folder exists, is not empty ({listed}) and was not "
                                 f"written by gmis (no {MARKER} file); choose a new folder",
                                 source=shown)
        _check_marked_contents(final, entries, command, shown)
        if entries and command == "simulate" and not overwrite:
            raise GmisInputError("output folder holds an earlier gmis output; use "
                                 "--overwrite to replace it", source=shown)
    _probe_writable(final.parent if final.parent.exists() else existing, shown)
    return final


def marker_info(folder) -> dict | None:
    """The marker file's JSON ({"command", "files", ...}), None when absent or unreadable."""
    try:
        info = json.loads((Path(folder) / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return info if isinstance(info, dict) else None


def _check_marked_contents(final: Path, entries, command: str, shown: str) -> None:
    """A marked folder is replaced only by the command that wrote it (the Python API,
    "python", by any) and only while it holds nothing gmis did not write there."""
    info = marker_info(final)
    if entries and info is None:          # a report / rtk folder: signed, not marked
        signed = signed_command(final)
        if signed is not None and signed != command and command != "python":
            raise GmisInputError(f"output folder holds the results of `gmis {signed}`; a "
                                 "command replaces only its own earlier results: choose a "
                                 "new folder", source=shown)
    if not entries or info is None:
        return
    other = info.get("command")
    if isinstance(other, str) and other != command and "python" not in (other, command):
        raise GmisInputError(f"output folder holds the results of `gmis {other}`; a command "
                             "replaces only its own earlier results: choose a new folder",
                             source=shown)
    files = info.get("files")
    if not isinstance(files, list):        # a marker of an older gmis: no list to check
        return
    extra = [e for e in entries if e != MARKER and e not in files
             and not ((final / e).is_dir() and is_gmis_folder(final / e))]
    if extra:
        listed = ", ".join(extra[:3]) + (", ..." if len(extra) > 3 else "")
        raise GmisInputError(f"output folder holds files gmis did not write ({listed}); "
                             "replacing it would delete them: choose a new folder or move "
                             "them", source=shown)


def claim(path, command: str) -> None:
    """Let :func:`gmis.results.results_directory` write ``path`` for ``command``: it marks
    the folder and re-checks it just before replacing an existing one. Kept under the
    absolute and the real path (a path through a symbolic link is found either way)."""
    _claims[_resolve(path)] = command
    _claims[Path(os.path.realpath(_resolve(path)))] = command


def release(path) -> None:
    _claims.pop(_resolve(path), None)
    _claims.pop(Path(os.path.realpath(_resolve(path))), None)


def claimed_command(path) -> str | None:
    return _claims.get(_resolve(path), _claims.get(Path(os.path.realpath(_resolve(path)))))


def mark(folder, command: str) -> Path | None:
    """Write the marker file that makes ``folder`` a gmis output folder (nothing when
    ``folder`` is not a folder)."""
    from gmis import __version__

    if not Path(folder).is_dir() or command in SELF_SIGNED_COMMANDS:
        return None
    marker = Path(folder) / MARKER
    files = sorted(e for e in os.listdir(folder) if e != MARKER)
    marker.write_text(json.dumps({"written_by": "gmis", "command": command,
                                  "version": __version__, "files": files}) + "\n",
                      encoding="utf-8")
    return marker


def check_and_claim(path, command: str, inputs=(), overwrite: bool = False) -> Path:
    final = check_output_folder(path, command, inputs, overwrite)
    claim(final, command)
    return final
