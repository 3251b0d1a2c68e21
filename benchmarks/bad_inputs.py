"""Bad inputs through the real command line, one case at a time (issue 16 acceptance).

Each case builds its input in a fresh folder (a copy of a simulated dataset or of the
RTKLIB test RINEX files from ../shared/data/rtklib-test, then one thing broken), runs
``python -m gmis ...`` in a subprocess and records

* the exit code and the last line on stderr (the message),
* whether a Python traceback was printed,
* whether anything was written (a file that did not exist before),
* whether every user file that existed before is still there, unchanged,
* for exit 0: whether any output file holds a non-finite number or a physically
  impossible value (|lat| > 90°, height outside -500..9000 m, speed > 150 m/s).

Usage (from the repository root; ~15-30 min of wall time on a loaded 2-core machine):

    PYTHONPATH=$PWD python3 benchmarks/bad_inputs.py [--only SUBSTRING] [--json out.json]

Prints a Markdown table and the totals; exits 1 if a case printed a traceback, lost a
user file, or exited 0 with non-finite or impossible output. Cases needing root (read-only
and full tmpfs mounts) or ../shared/data are skipped with the reason.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"
RTKLIB = SHARED / "rtklib-test"
T_START = 345600.0
SHORT_END = T_START + 320.0   # 300 s static alignment + 20 s of motion: a quick full run


# ----------------------------------------------------------------------------- material


class Material:
    """Built once: a simulated dataset (default scenario) and the RTKLIB RINEX files."""

    def __init__(self, root: Path):
        self.root = root
        self.ds = root / "base-dataset"
        if not (self.ds / "recipe.toml").is_file():
            run_gmis(["simulate", "default", "-o", str(self.ds), "--quiet"], root)
        self.rinex = RTKLIB if (RTKLIB / "30400920.05o").is_file() else None


def run_gmis(argv, cwd, timeout=1800):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "gmis", *argv], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout, check=False)
    return proc, time.perf_counter() - t0


def copy_dataset(m: Material, dst: Path, short: bool = False) -> Path:
    shutil.copytree(m.ds, dst, ignore=shutil.ignore_patterns(".gmis-output", "truth.npz",
                                                             "scenario.toml"))
    if short:
        edit(dst / "recipe.toml", "end_gps_s = 346200.0", f"end_gps_s = {SHORT_END}")
    return dst / "recipe.toml"


def copy_rinex(m: Material, dst: Path, nav: str = "07590920.05n") -> Path:
    dst.mkdir(parents=True)
    for name in ("30400920.05o", "07590920.05o", nav):
        shutil.copy(m.rinex / name, dst / name)
        os.chmod(dst / name, 0o644)
    recipe = dst / "recipe.toml"
    recipe.write_text(f"""[dataset]
name = "bad-input-rtk"
[paths]
rover_obs = "30400920.05o"
base_obs = "07590920.05o"
nav = "{nav}"
[base]
ecef_m = [-3976219.5082, 3382372.5671, 3652512.9849]
""")
    return recipe


def edit(path: Path, old: str, new: str, count: int = 1) -> None:
    text = path.read_text()
    if old not in text:
        raise RuntimeError(f"case setup: {old!r} not in {path}")
    path.write_text(text.replace(old, new, count))


def lines_of(path: Path) -> list[str]:
    return path.read_text().splitlines(keepends=True)


def set_cell(path: Path, line_no: int, col: int, value: str) -> None:
    lines = lines_of(path)
    cells = lines[line_no - 1].rstrip("\n").split(",")
    cells[col] = value
    lines[line_no - 1] = ",".join(cells) + "\n"
    path.write_text("".join(lines))


def map_column(path: Path, col: int, fn) -> None:
    lines = lines_of(path)
    out = [lines[0]]
    for line in lines[1:]:
        cells = line.rstrip("\n").split(",")
        cells[col] = fn(cells[col])
        out.append(",".join(cells) + "\n")
    path.write_text("".join(out))


_EPOCH_V2 = re.compile(r"^ \d\d [ \d]\d [ \d]\d [ \d]\d [ \d]\d [ \d]\d\.\d{7}  \d")


def epoch_lines(path: Path) -> list[int]:
    return [i for i, line in enumerate(lines_of(path)) if _EPOCH_V2.match(line)]


def header_end(path: Path) -> int:
    return next(i for i, line in enumerate(lines_of(path)) if "END OF HEADER" in line)


def keep_lines(path: Path, a: int, b: int | None = None, cut_last: int | None = None):
    lines = lines_of(path)[a:b]
    if cut_last is not None and lines:
        lines[-1] = lines[-1][:cut_last]
    path.write_text("".join(lines))


def repeat_line(path: Path, i: int) -> None:
    lines = lines_of(path)
    path.write_text("".join(lines[:i + 1] + [lines[i]] + lines[i + 1:]))


def swap_epochs(path: Path, k: int) -> None:
    """Epoch k+1 before epoch k (time goes backwards)."""
    ls, ep = lines_of(path), epoch_lines(path)
    a, b, c = ep[k], ep[k + 1], ep[k + 2]
    path.write_text("".join(ls[:a] + ls[b:c] + ls[a:b] + ls[c:]))


def duplicate_epoch(path: Path, k: int) -> None:
    ls, ep = lines_of(path), epoch_lines(path)
    a, b = ep[k], ep[k + 1]
    path.write_text("".join(ls[:b] + ls[a:b] + ls[b:]))


def second_60(path: Path, k: int) -> None:
    """Epoch k's seconds field set to 60.0000000 (a UTC leap second written as such)."""
    ls = lines_of(path)
    i = epoch_lines(path)[k]
    ls[i] = ls[i][:16] + "60.0000000" + ls[i][26:]
    path.write_text("".join(ls))


def obs_epochs(path: Path, first: int, last: int | None) -> None:
    """Keep the header and epochs [first, last) of a RINEX 2 observation file."""
    lines = lines_of(path)
    h = header_end(path) + 1
    ep = epoch_lines(path) + [len(lines)]
    last = len(ep) - 1 if last is None else last
    path.write_text("".join(lines[:h] + lines[ep[first]:ep[last]]))


# ----------------------------------------------------------------------------- cases
# Each case: (name, group, setup(m, d) -> (argv, cwd, expected output path or None))

CASES = []


def case(name, group, needs=None):
    def register(fn):
        CASES.append((name, group, needs, fn))
        return fn
    return register


def user_file(folder: Path, name="thesis.tex", text="my thesis\n") -> None:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_text(text)


def refused_output_case(name, command, out, user_file_name=None):
    """Register a case: `command <dataset copy> -o out --quiet` run from the work folder
    (holding the user file ``user_file_name`` when given), no output folder expected."""
    def make(m, d):
        r = copy_dataset(m, d / "ds")
        if user_file_name:
            user_file(d, user_file_name)
        return [command, str(r), "-o", out, "--quiet"], d, None
    case(name, "output")(make)


# --- output folders
@case("run -o . (cwd holds thesis.tex and a subfolder)", "output")
def _(m, d):
    r = copy_dataset(m, d / "ds")
    user_file(d / "s")
    user_file(d / "s" / "chapter1", "intro.tex")
    return ["run", str(r), "-o", ".", "--quiet"], d / "s", None


refused_output_case("run -o <dataset folder>", "run", "ds")


@case("run -o <parent of the dataset folder>", "output")
def _(m, d):
    r = copy_dataset(m, d / "proj" / "ds")
    return ["run", str(r), "-o", "proj", "--quiet"], d, None


@case("run -o .. (parent of cwd)", "output")
def _(m, d):
    r = copy_dataset(m, d / "ds")
    (d / "w").mkdir()
    return ["run", str(r), "-o", "..", "--quiet"], d / "w", None


@case("run -o existing folder with a user file", "output")
def _(m, d):
    r = copy_dataset(m, d / "ds")
    user_file(d / "out", "notes.txt")
    return ["run", str(r), "-o", "out", "--quiet"], d, None


@case("run -o existing folder with a user file, --overwrite-like re-run", "output")
def _(m, d):
    r = copy_dataset(m, d / "ds")
    user_file(d / "out", "summary.json", "{}\n")   # looks like results, not marked by gmis
    return ["run", str(r), "-o", "out", "--quiet"], d, None


refused_output_case("run -o a file", "run", "out.txt", user_file_name="out.txt")
refused_output_case("run -o a path below a file", "run", "out.txt/results",
                    user_file_name="out.txt")
refused_output_case("run -o /proc/x", "run", "/proc/gmis-x")
refused_output_case("run -o /sys/x (read-only sysfs)", "run", "/sys/gmis-x")


@case("run -o on a read-only file system", "output", needs="mount")
def _(m, d):
    r = copy_dataset(m, d / "ds")
    mnt = d / "ro"
    mnt.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(mnt)], check=True)
    return ["run", str(r), "-o", str(mnt / "out"), "--quiet"], d, None


@case("run -o on a full disk (64 kB tmpfs)", "output", needs="mount")
def _(m, d):
    r = copy_dataset(m, d / "ds", short=True)
    mnt = d / "full"
    mnt.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mnt)], check=True)
    return ["run", str(r), "-o", str(mnt / "out"), "--quiet"], d, None


@case("run -o new folder (control, short run)", "output")
def _(m, d):
    r = copy_dataset(m, d / "ds", short=True)
    return ["run", str(r), "-o", "out", "--quiet"], d, d / "out"


@case("run -o empty existing folder (short run)", "output")
def _(m, d):
    r = copy_dataset(m, d / "ds", short=True)
    (d / "out").mkdir()
    return ["run", str(r), "-o", "out", "--quiet"], d, d / "out"


@case("run -o folder written by gmis before (replaced, short run)", "output")
def _(m, d):
    r = copy_dataset(m, d / "ds", short=True)
    user_file(d / "out", "summary.json", "{}\n")
    (d / "out" / ".gmis-output").write_text('{"written_by": "gmis"}\n')
    return ["run", str(r), "-o", "out", "--quiet"], d, d / "out"


refused_output_case("vce -o <dataset folder>", "vce", "ds")


@case("outages -o . (cwd holds a user file)", "output")
def _(m, d):
    r = copy_dataset(m, d / "ds")
    user_file(d / "w")
    return ["outages", str(r), "-o", ".", "--quiet"], d / "w", None


@case("report run -o run (the folder being reported)", "output")
def _(m, d):
    user_file(d / "run", "solution.csv", "t\n1\n")
    (d / "run" / ".gmis-output").write_text("{}\n")
    return ["report", "run", "-o", "run"], d, None


@case("report run -o . (cwd)", "output")
def _(m, d):
    user_file(d / "run", "solution.csv", "t\n1\n")
    return ["report", str(d / "run"), "-o", "."], d / "run", None


@case("report of a folder that is not a results folder", "output")
def _(m, d):
    user_file(d / "notes")
    return ["report", "notes"], d, None


@case("simulate -o folder with user files --overwrite", "output")
def _(m, d):
    user_file(d / "mine")
    return ["simulate", "default", "-o", "mine", "--overwrite", "--quiet"], d, None


@case("simulate -o .", "output")
def _(m, d):
    user_file(d / "w")
    return ["simulate", "default", "-o", ".", "--quiet"], d / "w", None


@case("rtk default (offered by --help before)", "output")
def _(m, d):
    return ["rtk", "default", "--quiet"], d, None


@case("rtk -o <RINEX folder>", "output", needs="rinex")
def _(m, d):
    r = copy_rinex(m, d / "gnss")
    return ["rtk", str(r), "-o", "gnss", "--quiet"], d, None


@case("run -o '' (empty name)", "output")
def _(m, d):
    r = copy_dataset(m, d / "ds")
    user_file(d)
    return ["run", str(r), "-o", "", "--quiet"], d, None


# --- IMU file
def broken_dataset_case(name, group, change, short=False, expect_output=False):
    """Register a case: `gmis run` on a dataset copy that ``change(dataset folder)`` broke;
    a results folder is expected only with expect_output."""
    @case(name, group)
    def _(m, d):
        r = copy_dataset(m, d / "ds", short=short)
        change(d / "ds")
        return ["run", str(r), "-o", str(d / "out"), "--quiet"], d, \
            (d / "out" if expect_output else None)


def imu_case(name, change, short=False, expect_output=False):
    broken_dataset_case(name, "imu", change, short, expect_output)


def _del_lines(a, b):
    def change(ds):
        lines = lines_of(ds / "imu.csv")
        del lines[a - 1:b]
        (ds / "imu.csv").write_text("".join(lines))
    return change


imu_case("IMU gap: lines 35001-55000 deleted (200 s)", _del_lines(35001, 55000))
imu_case("IMU gap: 2 s (lines 30502-30701 deleted, in the window)", _del_lines(30502, 30701),
         short=True)
imu_case("IMU gap: 0.5 s (lines 30502-30551 deleted) — flagged, bridged", _del_lines(30502,
         30551), short=True, expect_output=True)
imu_case("IMU gyro_unit = deg/s on rad/s data",
         lambda ds: edit(ds / "recipe.toml", 'gyro_unit = "rad/s"', 'gyro_unit = "deg/s"'))
imu_case("IMU accel_unit = g on m/s² data",
         lambda ds: edit(ds / "recipe.toml", 'accel_unit = "m/s^2"', 'accel_unit = "g"'))
imu_case("IMU gyro and accel columns swapped in the recipe",
         lambda ds: edit(ds / "recipe.toml", 'gyro_columns = ["gyro_x", "gyro_y", "gyro_z"]\n'
                         'accel_columns = ["accel_x", "accel_y", "accel_z"]',
                         'gyro_columns = ["accel_x", "accel_y", "accel_z"]\n'
                         'accel_columns = ["gyro_x", "gyro_y", "gyro_z"]'))
imu_case("IMU accel 1e300", lambda ds: set_cell(ds / "imu.csv", 1001, 5, "1e300"))
imu_case("IMU gyro 1e5 rad/s", lambda ds: set_cell(ds / "imu.csv", 1001, 2, "1e5"))
imu_case("IMU NaN cell", lambda ds: set_cell(ds / "imu.csv", 1001, 3, "nan"))
imu_case("IMU inf cell", lambda ds: set_cell(ds / "imu.csv", 1001, 3, "inf"))
imu_case("IMU empty cell", lambda ds: set_cell(ds / "imu.csv", 1001, 3, ""))
imu_case("IMU time backwards", lambda ds: set_cell(ds / "imu.csv", 2001, 0, "345600.5"))
imu_case("IMU duplicated epoch (line repeated)", lambda ds: repeat_line(ds / "imu.csv", 2999))
imu_case("IMU leap second: UTC stamp repeats a second", lambda ds: map_column(
    ds / "imu.csv", 0, lambda c: f"{float(c) - 1.0:.6f}" if float(c) >= 345700.0 else c))
imu_case("IMU time jump +3600 s in the middle", lambda ds: map_column(
    ds / "imu.csv", 0, lambda c: f"{float(c) + 3600.0:.6f}" if float(c) >= 345700.0 else c))
imu_case("IMU time in ms (x1000)", lambda ds: map_column(
    ds / "imu.csv", 0, lambda c: f"{float(c) * 1000.0:.3f}"))
imu_case("IMU truncated last line", lambda ds: (ds / "imu.csv").write_text(
    (ds / "imu.csv").read_text()[:-25]))
imu_case("IMU truncated in the middle (half the file)", lambda ds: (ds / "imu.csv").write_text(
    (ds / "imu.csv").read_text()[:len((ds / "imu.csv").read_text()) // 2]))
imu_case("IMU CRLF line endings", lambda ds: (ds / "imu.csv").write_bytes(
    (ds / "imu.csv").read_bytes().replace(b"\n", b"\r\n")), short=True, expect_output=True)
imu_case("IMU mixed line endings (every 3rd CRLF, some CR)", lambda ds: (ds / "imu.csv")
         .write_bytes(b"".join(
             line + (b"\r\n" if i % 3 == 0 else b"\r" if i % 7 == 0 else b"\n")
             for i, line in enumerate((ds / "imu.csv").read_bytes().split(b"\n")[:-1]))),
         short=True, expect_output=True)
imu_case("IMU UTF-8 BOM", lambda ds: (ds / "imu.csv").write_bytes(
    b"\xef\xbb\xbf" + (ds / "imu.csv").read_bytes()), short=True, expect_output=True)
imu_case("IMU UTF-16 encoded", lambda ds: (ds / "imu.csv").write_bytes(
    (ds / "imu.csv").read_text().encode("utf-16")))
imu_case("IMU binary garbage", lambda ds: (ds / "imu.csv").write_bytes(os.urandom(200_000)))
imu_case("IMU empty file", lambda ds: (ds / "imu.csv").write_text(""))
imu_case("IMU header only", lambda ds: (ds / "imu.csv").write_text(
    lines_of(ds / "imu.csv")[0]))
imu_case("IMU one 20 MB line", lambda ds: (ds / "imu.csv").write_text(
    lines_of(ds / "imu.csv")[0] + "1," * 10_000_000 + "\n"))
imu_case("IMU huge file: data repeated 6x (time backwards at the seam)", lambda ds: (
    ds / "imu.csv").write_text(lines_of(ds / "imu.csv")[0]
                               + "".join(lines_of(ds / "imu.csv")[1:]) * 6))
imu_case("IMU semicolon delimiter", lambda ds: (ds / "imu.csv").write_text(
    (ds / "imu.csv").read_text().replace(",", ";")))
imu_case("IMU extra column on one line", lambda ds: set_cell(ds / "imu.csv", 501, 6,
                                                             "9.8,1.0"))
imu_case("IMU a folder instead of a file", lambda ds: ((ds / "imu.csv").unlink(),
                                                      (ds / "imu.csv").mkdir()))
imu_case("IMU only 1 sample in the [time] window", lambda ds: edit(
    ds / "recipe.toml", "end_gps_s = 346200.0", "end_gps_s = 345600.001"))


# --- GNSS / heading / reference files
def gnss_case(name, change, group="gnss"):
    broken_dataset_case(name, group, change)


gnss_case("GNSS lat/lon headers swapped", lambda ds: edit(
    ds / "gnss.csv", "time_gps_s,lat_deg,lon_deg", "time_gps_s,lon_deg,lat_deg"))
gnss_case("GNSS height 1e12", lambda ds: set_cell(ds / "gnss.csv", 101, 3, "1e12"))
gnss_case("GNSS height -1e4", lambda ds: set_cell(ds / "gnss.csv", 101, 3, "-10000"))
gnss_case("GNSS sigma 1e9 m", lambda ds: set_cell(ds / "gnss.csv", 101, 4, "1e9"))
gnss_case("GNSS sigma 0", lambda ds: set_cell(ds / "gnss.csv", 101, 4, "0"))
gnss_case("GNSS negative velocity sigma", lambda ds: set_cell(ds / "gnss.csv", 101, 10, "-1"))
gnss_case("GNSS velocity 1e4 m/s", lambda ds: set_cell(ds / "gnss.csv", 101, 7, "1e4"))
gnss_case("GNSS position jump 1 degree", lambda ds: map_column(
    ds / "gnss.csv", 1, lambda c: f"{float(c) + 1.0:.11f}" if c.startswith("43.77") and
    hash(c) % 50 == 0 else c))
gnss_case("GNSS latitude 95", lambda ds: set_cell(ds / "gnss.csv", 101, 1, "95"))
gnss_case("GNSS time as seconds of day (no overlap)", lambda ds: map_column(
    ds / "gnss.csv", 0, lambda c: f"{float(c) - 345600.0:.3f}"))
gnss_case("GNSS duplicated epoch", lambda ds: repeat_line(ds / "gnss.csv", 49))
gnss_case("GNSS empty file", lambda ds: (ds / "gnss.csv").write_text(""))
gnss_case("GNSS unknown column", lambda ds: edit(ds / "gnss.csv", "h_m,", "height,"))
gnss_case("GNSS BOM + CRLF", lambda ds: (ds / "gnss.csv").write_bytes(
    b"\xef\xbb\xbf" + (ds / "gnss.csv").read_bytes().replace(b"\n", b"\r\n")))
gnss_case("origin 500 km away", lambda ds: edit(ds / "recipe.toml", "lat_deg = 43.7735",
                                                "lat_deg = 48.2735"))
gnss_case("heading.csv in radians", lambda ds: map_column(
    ds / "heading.csv", 1, lambda c: f"{float(c) * 0.017453292519943295:.7f}"), "heading")
gnss_case("heading 1000 deg", lambda ds: set_cell(ds / "heading.csv", 101, 1, "1000"),
          "heading")
gnss_case("heading sigma 500 deg", lambda ds: set_cell(ds / "heading.csv", 101, 2, "500"),
          "heading")
gnss_case("heading time backwards", lambda ds: set_cell(ds / "heading.csv", 101, 0,
                                                        "345601.0"), "heading")
gnss_case("reference height 1e12", lambda ds: set_cell(ds / "reference.csv", 101, 3, "1e12"),
          "reference")


# --- recipes
def recipe_case(name, change):
    @case(name, "recipe")
    def _(m, d):
        r = copy_dataset(m, d / "ds")
        change(r)
        return ["run", str(r), "-o", str(d / "out"), "--quiet"], d, None


recipe_case("recipe not TOML", lambda r: r.write_text("this is [not toml\n"))
recipe_case("recipe UTF-8 BOM", lambda r: r.write_bytes(b"\xef\xbb\xbf" + r.read_bytes()))
recipe_case("recipe binary", lambda r: r.write_bytes(os.urandom(3000)))
recipe_case("recipe empty", lambda r: r.write_text(""))
recipe_case("recipe unknown key", lambda r: edit(r, "rate_hz = 100.0",
                                                 "rate_hz = 100.0\nrate_hx = 1"))
recipe_case("recipe rate_hz = -100", lambda r: edit(r, "rate_hz = 100.0", "rate_hz = -100.0"))
recipe_case("recipe rate_hz = nan", lambda r: edit(r, "rate_hz = 100.0", "rate_hz = nan"))
recipe_case("recipe start > end", lambda r: edit(r, "start_gps_s = 345600.0",
                                                 "start_gps_s = 346300.0"))
recipe_case("recipe lever arm 1e6 m", lambda r: edit(r, "primary_lever_arm_m = [0.3, 1.0, 1.5]",
                                                     "primary_lever_arm_m = [0.3, 1.0, 1e6]"))
recipe_case("recipe imu path is a folder", lambda r: edit(r, 'imu = "imu.csv"', 'imu = "."'))
recipe_case("recipe origin latitude 123", lambda r: edit(r, "lat_deg = 43.7735",
                                                         "lat_deg = 123.0"))


@case("recipe path is a folder", "recipe")
def _(m, d):
    copy_dataset(m, d / "ds")
    return ["run", str(d / "ds"), "-o", str(d / "out"), "--quiet"], d, None


@case("recipe does not exist", "recipe")
def _(m, d):
    return ["run", str(d / "nope.toml"), "-o", str(d / "out"), "--quiet"], d, None


@case("scenario file not TOML (simulate)", "recipe")
def _(m, d):
    (d / "s.toml").write_text("[scenario\n")
    return ["simulate", "s.toml", "-o", "x", "--quiet"], d, None


@case("scenario file with an unknown section (simulate)", "recipe")
def _(m, d):
    (d / "s.toml").write_text("[scenari]\nname = 'x'\n")
    return ["simulate", "s.toml", "-o", "x", "--quiet"], d, None


# --- RINEX / RTK
def rtk_case(name, change, nav="07590920.05n", tight=False, expect_output=False):
    @case(name, "rinex", needs="rinex")
    def _(m, d):
        r = copy_rinex(m, d / "gnss", nav=nav)
        change(d / "gnss", r)
        return ["rtk", str(r), "-o", str(d / "out"), "--quiet"] + (["--tight"] if tight else []), \
            d, (d / "out" if expect_output else None)


ROVER, BASE, NAV = "30400920.05o", "07590920.05o", "07590920.05n"


def _rtk_opt(text):
    return lambda g, r: r.write_text(r.read_text() + f"[rtk]\n{text}\n")


rtk_case("rtk control run (RTKLIB test data)", lambda g, r: None, expect_output=True)
rtk_case("rtk [rtk] elevation_mask_deg = 89", _rtk_opt("elevation_mask_deg = 89"))
rtk_case("rtk --tight elevation_mask_deg = 89", _rtk_opt("elevation_mask_deg = 89"), tight=True)
rtk_case("rtk [rtk] elevation_mask_deg = 100", _rtk_opt("elevation_mask_deg = 100"))
rtk_case("rtk [rtk] elevation_mask_deg = -5", _rtk_opt("elevation_mask_deg = -5"))
rtk_case("rtk [rtk] elevation_mask_deg = 'high'", _rtk_opt("elevation_mask_deg = 'high'"))
rtk_case("rtk [rtk] ratio_threshold = 0", _rtk_opt("ratio_threshold = 0"))
rtk_case("rtk [rtk] sigma_code_m = -1", _rtk_opt("sigma_code_m = -1"))
rtk_case("rtk [rtk] min_fix_satellites = 2.5", _rtk_opt("min_fix_satellites = 2.5"))
rtk_case("rtk 2010 nav file for 2005 data", lambda g, r: None, nav="brdc1820.10n")
rtk_case("rtk base and rover without common epochs", lambda g, r: (
    obs_epochs(g / ROVER, 0, 60), obs_epochs(g / BASE, 60, None)))
rtk_case("rtk one-epoch rover file", lambda g, r: obs_epochs(g / ROVER, 0, 1))
rtk_case("rtk rover truncated inside the header", lambda g, r: keep_lines(
    g / ROVER, 0, header_end(g / ROVER) // 2))
rtk_case("rtk rover truncated right after END OF HEADER", lambda g, r: keep_lines(
    g / ROVER, 0, header_end(g / ROVER) + 1))
rtk_case("rtk rover without END OF HEADER", lambda g, r: edit(
    g / ROVER, "END OF HEADER", "END OF HEADEX"))
rtk_case("rtk rover truncated inside an epoch line", lambda g, r: keep_lines(
    g / ROVER, 0, epoch_lines(g / ROVER)[50] + 1, cut_last=20))
rtk_case("rtk rover truncated inside an observation record", lambda g, r: keep_lines(
    g / ROVER, 0, epoch_lines(g / ROVER)[50] + 3, cut_last=30))
rtk_case("rtk rover last line cut", lambda g, r: (g / ROVER).write_text(
    (g / ROVER).read_text()[:-40]))
rtk_case("rtk rover CRLF line endings", lambda g, r: (g / ROVER).write_bytes(
    (g / ROVER).read_bytes().replace(b"\n", b"\r\n")))
rtk_case("rtk rover UTF-8 BOM", lambda g, r: (g / ROVER).write_bytes(
    b"\xef\xbb\xbf" + (g / ROVER).read_bytes()))
rtk_case("rtk rover epochs out of order", lambda g, r: swap_epochs(g / ROVER, 10))
rtk_case("rtk rover duplicated epoch", lambda g, r: duplicate_epoch(g / ROVER, 10))
rtk_case("rtk rover epoch at second 60 (leap second)", lambda g, r: second_60(g / ROVER, 30))
rtk_case("rtk rover empty file", lambda g, r: (g / ROVER).write_text(""))
rtk_case("rtk rover is a nav file", lambda g, r: shutil.copy(g / NAV, g / ROVER))
rtk_case("rtk rover binary garbage", lambda g, r: (g / ROVER).write_bytes(os.urandom(50_000)))
rtk_case("rtk rover .gz that is not gzip", lambda g, r: (
    shutil.move(g / ROVER, g / "30400920.05o.gz"),
    edit(r, 'rover_obs = "30400920.05o"', 'rover_obs = "30400920.05o.gz"')))
rtk_case("rtk nav truncated inside a record", lambda g, r: (g / NAV).write_text(
    (g / NAV).read_text()[: len((g / NAV).read_text()) // 2 + 37]))
rtk_case("rtk nav header only", lambda g, r: keep_lines(g / NAV, 0, header_end(g / NAV) + 1))
rtk_case("rtk nav empty", lambda g, r: (g / NAV).write_text(""))
rtk_case("rtk base ECEF at the earth's centre", lambda g, r: edit(
    r, "ecef_m = [-3976219.5082, 3382372.5671, 3652512.9849]", "ecef_m = [0, 0, 0]"))
rtk_case("rtk base 500 km off", lambda g, r: edit(
    r, "ecef_m = [-3976219.5082, 3382372.5671, 3652512.9849]",
    "ecef_m = [-3676219.5082, 3682372.5671, 3652512.9849]"))


# ----------------------------------------------------------------------------- running


def snapshot(folder: Path) -> dict[str, str]:
    out = {}
    for p in folder.rglob("*"):
        if p.is_file() and not p.is_symlink():
            try:
                out[str(p.relative_to(folder))] = hashlib.sha1(p.read_bytes()).hexdigest()
            except OSError:
                pass
    return out


_NUMBER = re.compile(r"(?i)(?<![a-z_])(nan|inf|infinity)(?![a-z_])")


def output_problems(out: Path) -> list[str]:
    """Non-finite or physically impossible values in the CSV/.pos/JSON files of out."""
    import numpy as np
    problems = []
    for p in sorted(out.rglob("*")):
        if p.suffix not in (".csv", ".pos", ".json") or not p.is_file():
            continue
        text = p.read_text(errors="replace")
        if p.suffix != ".json" and _NUMBER.search(text):
            problems.append(f"{p.name}: non-finite value")
        if p.suffix == ".csv":
            lines = text.splitlines()
            if len(lines) < 2:
                continue
            names = lines[0].split(",")
            try:
                data = np.loadtxt(p, delimiter=",", skiprows=1, ndmin=2)
            except ValueError:
                problems.append(f"{p.name}: unreadable numbers")
                continue
            for j, name in enumerate(names):
                col = data[:, j]
                if name == "lat_deg" and (np.abs(col) > 90).any():
                    problems.append(f"{p.name}: {name} out of range")
                if name == "h_m" and ((col < -500) | (col > 9000)).any():
                    problems.append(f"{p.name}: {name} {col.min():.3g}..{col.max():.3g}")
            vel = [j for j, n in enumerate(names) if n in ("ve_m_s", "vn_m_s", "vu_m_s")]
            if len(vel) == 3 and (np.linalg.norm(data[:, vel], axis=1) > 150).any():
                problems.append(f"{p.name}: speed > 150 m/s")
        if p.name == "summary.json":
            stats = json.loads(text)
            err = stats.get("errors_vs_reference", {}) if isinstance(stats, dict) else {}
            if "null" in json.dumps(err):
                problems.append("summary.json: null (NaN) error statistic")
    return problems


def have_mount() -> bool:
    return os.geteuid() == 0 and shutil.which("mount") is not None


def run_case(m, root, name, group, needs, setup):
    d = Path(tempfile.mkdtemp(prefix="case-", dir=root))
    row = {"case": name, "group": group}
    if needs == "rinex" and m.rinex is None:
        return dict(row, skipped="../shared/data/rtklib-test absent")
    if needs == "mount" and not have_mount():
        return dict(row, skipped="needs root and mount for a tmpfs")
    mounts = []
    try:
        argv, cwd, expected_out = setup(m, d)
        mounts = [p for p in d.iterdir() if p.is_dir() and os.path.ismount(p)]
        before = snapshot(d)
        proc, wall = run_gmis(argv, cwd)
        after = snapshot(d)
        err = proc.stderr.replace(str(d), "<case>").strip().splitlines()
        row.update(argv="gmis " + " ".join(argv), exit=proc.returncode,
                   message=(err[-1] if err else ""),
                   stderr_lines=sum(not x.startswith("gmis: warning: ") for x in err),
                   warnings=sum(x.startswith("gmis: warning: ") for x in err),
                   traceback="Traceback" in proc.stderr, wall_s=round(wall, 1))
        written = sorted(set(after) - set(before))
        for mnt in mounts:
            written += [f"{mnt.name}/{p}" for p in snapshot(mnt)]
        outside = [p for p in ("/proc/gmis-x", "/sys/gmis-x") if os.path.exists(p)]
        row["written"] = len(written) + len(outside)
        lost = [p for p, h in before.items() if after.get(p) != h
                and not (expected_out is not None and
                         (d / p).resolve().is_relative_to(expected_out))]
        row["user_files_lost_or_changed"] = lost
        row["output_problems"] = []
        if proc.returncode == 0:
            out = expected_out or (cwd / argv[argv.index("-o") + 1] if "-o" in argv else None)
            if out is not None and Path(out).is_dir():
                row["output_problems"] = output_problems(Path(out))
    except subprocess.TimeoutExpired:
        row.update(exit="timeout", message="", traceback=False, written=0,
                   user_files_lost_or_changed=[], output_problems=[])
    finally:
        for mnt in mounts:
            subprocess.run(["umount", str(mnt)], check=False)
        shutil.rmtree(d, ignore_errors=True)
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", action="append",
                    help="run only the cases whose name contains this (repeatable)")
    ap.add_argument("--merge", help="a --json file of an earlier run: its rows stand for the "
                    "cases not run now (to re-run a few cases after a change)")
    ap.add_argument("--json", help="write the rows as JSON here")
    ap.add_argument("--workdir", help="keep the simulated base dataset here between runs")
    args = ap.parse_args(argv)
    root = Path(args.workdir) if args.workdir else Path(tempfile.mkdtemp(prefix="gmis-bad-"))
    root.mkdir(parents=True, exist_ok=True)
    m = Material(root)
    rows = []
    cases = [c for c in CASES if not args.only or any(o in c[0] for o in args.only)]
    earlier = {r["case"]: r for r in json.loads(Path(args.merge).read_text())} \
        if args.merge else {}
    selected = {c[0] for c in cases}
    for i, (name, group, needs, setup) in enumerate(CASES if earlier else cases, 1):
        if name not in selected:
            if name in earlier:
                rows.append(earlier[name])
            continue
        row = run_case(m, root, name, group, needs, setup)
        rows.append(row)
        print(f"[{i}/{len(CASES)}] {name}: exit {row.get('exit', 'skipped')} "
              f"{row.get('message', row.get('skipped', ''))[:150]}", file=sys.stderr, flush=True)
    ran = [r for r in rows if "skipped" not in r]
    bad_exit0 = [r for r in ran if r["exit"] == 0 and r["output_problems"]]
    tracebacks = [r for r in ran if r["traceback"]]
    lost = [r for r in ran if r["user_files_lost_or_changed"]]
    print("| # | group | case | exit | written | user files ok | message |")
    print("|---|---|---|---|---|---|---|")
    for i, r in enumerate(rows, 1):
        if "skipped" in r:
            print(f"| {i} | {r['group']} | {r['case']} | skipped | | | {r['skipped']} |")
            continue
        msg = r["message"].replace("|", "\\|")
        if len(msg) > 230:
            msg = msg[:227] + "..."
        if r["output_problems"]:
            msg += " **OUTPUT: " + "; ".join(r["output_problems"]) + "**"
        print(f"| {i} | {r['group']} | {r['case']} | {r['exit']} | "
              f"{'yes (' + str(r['written']) + ')' if r['written'] else 'no'} | "
              f"{'no: ' + ', '.join(r['user_files_lost_or_changed']) if r['user_files_lost_or_changed'] else 'yes'}"
              f" | {msg} |")
    print()
    print(f"cases: {len(rows)} ({len(ran)} run, {len(rows) - len(ran)} skipped); exit 0: "
          f"{sum(r['exit'] == 0 for r in ran)}, exit 2: {sum(r['exit'] == 2 for r in ran)}, "
          f"other: {sum(r['exit'] not in (0, 2) for r in ran)}")
    print(f"tracebacks: {len(tracebacks)}; runs with user files lost or changed: {len(lost)}; "
          f"exit 0 with non-finite or impossible output: {len(bad_exit0)}; "
          f"errors not on one line (besides 'gmis: warning:' lines): "
          f"{sum(r['exit'] == 2 and r['stderr_lines'] > 1 for r in ran)}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1) + "\n")
    if not args.workdir:
        shutil.rmtree(root, ignore_errors=True)
    return 1 if (tracebacks or lost or bad_exit0) else 0


if __name__ == "__main__":
    sys.exit(main())
