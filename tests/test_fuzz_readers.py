"""Fuzzing every reader (issue 16): each generated or mutated input yields a result or the
one-line GmisInputError, never another exception.

Seeds: a small valid dataset written from code (IMU/GNSS/heading/reference CSV, recipe),
the embedded default scenario, and small real RINEX 2/3 observation and navigation files
and SP3 files from ../shared/data (those tests skip when it is absent). Mutations: cut at
any point, delete/duplicate/swap lines, replace or insert characters (digits, signs,
separators, NUL, CR, non-ASCII), line endings CRLF/CR, a UTF-8 BOM. The examples are
derandomized so CI is reproducible; GMIS_FUZZ_EXAMPLES raises their number locally.

Each mutated input must give a result or the one-line input error (gnss.errors.GnssInputError,
of which gmis.errors.GmisInputError is one), never another exception.
"""

from __future__ import annotations

import os
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from gmis.readers import (
    load_dataset,
    read_gnss_solution,
    read_heading,
    read_imu,
    read_reference,
    read_table,
)
from gmis.recipe import ImuSection, load_recipe, read_toml
from gnss.errors import GnssInputError
from tests.shared_data import SHARED_DATA, require

EXAMPLES = int(os.environ.get("GMIS_FUZZ_EXAMPLES", "0")) or None
CORPUS = SHARED_DATA / "rinex-corpus-georinex"


def fuzz_settings(n: int, shrink: bool = True):
    """Derandomized (reproducible in CI), no example database written into the repository,
    no deadline (the machine is shared); shrink=False for the slow readers (RINEX, SP3,
    .pos), where shrinking a failure would only cost CI time."""
    phases = [Phase.explicit, Phase.generate] + ([Phase.shrink] if shrink else [])
    return settings(max_examples=EXAMPLES or n, deadline=None, derandomize=True,
                    database=None, phases=phases,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                           HealthCheck.function_scoped_fixture])


# ----------------------------------------------------------------------------- mutations

_CHARS = list("0123456789-+.eE ,;\t#\"'=[]") + ["\r", "\n", "\x00", "é", "∞", "nan", "inf",
                                                 "1e999", "-0", ""]
_fraction = st.floats(0.0, 1.0, allow_nan=False)
_edit = st.one_of(
    st.tuples(st.just("cut"), _fraction),
    st.tuples(st.just("delete_line"), _fraction),
    st.tuples(st.just("duplicate_line"), _fraction),
    st.tuples(st.just("swap_lines"), _fraction, _fraction),
    st.tuples(st.just("replace"), _fraction, st.sampled_from(_CHARS)),
    st.tuples(st.just("insert"), _fraction, st.text(max_size=12)),
    st.tuples(st.just("crlf")),
    st.tuples(st.just("cr")),
    st.tuples(st.just("bom")),
)
edits = st.lists(_edit, min_size=1, max_size=4)


def mutate(text: str, edit_list) -> str:
    for e in edit_list:
        kind = e[0]
        lines = text.splitlines(keepends=True)
        if kind == "cut":
            text = text[:int(e[1] * len(text))]
        elif kind in ("delete_line", "duplicate_line") and lines:
            i = min(int(e[1] * len(lines)), len(lines) - 1)
            lines[i:i + 1] = [] if kind == "delete_line" else [lines[i], lines[i]]
            text = "".join(lines)
        elif kind == "swap_lines" and lines:
            i, j = (min(int(f * len(lines)), len(lines) - 1) for f in e[1:])
            lines[i], lines[j] = lines[j], lines[i]
            text = "".join(lines)
        elif kind == "replace" and text:
            i = min(int(e[1] * len(text)), len(text) - 1)
            text = text[:i] + e[2] + text[i + 1:]
        elif kind == "insert":
            i = int(e[1] * len(text))
            text = text[:i] + e[2] + text[i:]
        elif kind == "crlf":
            text = text.replace("\r\n", "\n").replace("\n", "\r\n")
        elif kind == "cr":
            text = text.replace("\n", "\r")
        elif kind == "bom":
            text = "\ufeff" + text
    return text


def write(path: Path, text: str) -> Path:
    path.write_bytes(text.encode("utf-8", errors="surrogatepass"))
    return path


def result_or_input_error(fn, *args, **kwargs):
    """Call fn; the input error (gnss.errors.GnssInputError, of which gmis's GmisInputError
    is one: the CLI prints it as one line) is a valid outcome, anything else fails."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return fn(*args, **kwargs)
        except GnssInputError as exc:
            return exc


# ----------------------------------------------------------------------------- CSV seeds

T0 = 345600.0


def _csv(header, rows):
    return ",".join(header) + "\n" + "".join(",".join(repr(float(x)) for x in r) + "\n"
                                             for r in rows)


def imu_seed(n=60):
    k = np.arange(n)
    rows = np.column_stack([T0 + k / 100.0, 1e-3 * np.sin(k), 2e-3 * np.cos(k),
                            1e-3 * k / n, 0.1 + 0 * k, 0.2 + 0 * k, 9.8 + 1e-3 * k])
    return _csv(["time_gps_s", "gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"],
                rows)


def gnss_seed(n=6):
    t = T0 + 0.1 * np.arange(n)
    rows = np.column_stack([t, 43.7735 + 1e-7 * np.arange(n), np.full(n, -79.5019),
                            np.full(n, 180.0), np.full((n, 3), 0.02), np.zeros((n, 3)),
                            np.full((n, 3), 0.05)])
    return _csv(["time_gps_s", "lat_deg", "lon_deg", "h_m", "sigma_e_m", "sigma_n_m",
                 "sigma_u_m", "ve_m_s", "vn_m_s", "vu_m_s", "sigma_ve_m_s", "sigma_vn_m_s",
                 "sigma_vu_m_s"], rows)


def heading_seed(n=6):
    t = T0 + 0.1 * np.arange(n)
    return _csv(["time_gps_s", "heading_deg", "sigma_heading_deg"],
                np.column_stack([t, np.full(n, 90.0), np.full(n, 0.5)]))


def reference_seed(n=6):
    t = T0 + 0.1 * np.arange(n)
    rows = np.column_stack([t, np.full(n, 43.7735), np.full(n, -79.5019), np.full(n, 180.0),
                            np.zeros((n, 3)), np.zeros(n), np.zeros(n), np.full(n, 90.0)])
    return _csv(["time_gps_s", "lat_deg", "lon_deg", "h_m", "ve_m_s", "vn_m_s", "vu_m_s",
                 "pitch_deg", "roll_deg", "heading_deg"], rows)


RECIPE_SEED = """[dataset]
name = "fuzz"
[paths]
imu = "imu.csv"
gnss_solution = "gnss.csv"
heading = "heading.csv"
reference = "reference.csv"
[time]
start_gps_s = 345600.0
[origin]
lat_deg = 43.7735
lon_deg = -79.5019
h_m = 180.0
[imu]
rate_hz = 100.0
gyro_unit = "rad/s"
accel_unit = "m/s^2"
[antennas]
primary_lever_arm_m = [0.1, 0.2, 1.5]
[filter]
mode = "loose"
"""


@pytest.fixture(scope="module")
def folder():
    with tempfile.TemporaryDirectory(prefix="gmis-fuzz-") as d:
        yield Path(d)


def _imu_section():
    return ImuSection(rate_hz=100.0)


# ----------------------------------------------------------------------------- CSV readers

CSV_READERS = {
    "imu": (imu_seed, lambda p: read_imu(p, _imu_section())),
    "gnss": (gnss_seed, read_gnss_solution),
    "heading": (heading_seed, read_heading),
    "reference": (reference_seed, read_reference),
}


@pytest.mark.parametrize("kind", sorted(CSV_READERS))
def test_csv_seed_is_valid(folder, kind):
    seed, reader = CSV_READERS[kind]
    assert not isinstance(reader(write(folder / f"{kind}.csv", seed())), Exception)


@pytest.mark.parametrize("kind", sorted(CSV_READERS))
@fuzz_settings(60)
@given(edit_list=edits)
def test_mutated_csv_gives_result_or_input_error(folder, kind, edit_list):
    seed, reader = CSV_READERS[kind]
    path = write(folder / f"m-{kind}.csv", mutate(seed(), edit_list))
    result_or_input_error(reader, path)


_cell = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64),
                  st.integers(-10**30, 10**30), st.sampled_from(["", "x", "1.0.0", "--1",
                                                                  "0x10", "1_000", " "]))


@fuzz_settings(60)
@given(kind=st.sampled_from(sorted(CSV_READERS)),
       columns=st.integers(1, 14), rows=st.lists(st.lists(_cell, min_size=1, max_size=14),
                                                  max_size=8),
       header_from_seed=st.booleans())
def test_generated_tables_give_result_or_input_error(folder, kind, columns, rows,
                                                     header_from_seed):
    seed, reader = CSV_READERS[kind]
    header = seed().splitlines()[0].split(",")[:columns] if header_from_seed else \
        [f"c{j}" for j in range(columns)]
    text = ",".join(header) + "\n" + "".join(",".join(map(str, r)) + "\n" for r in rows)
    result_or_input_error(reader, write(folder / f"g-{kind}.csv", text))


@fuzz_settings(40)
@given(text=st.text(max_size=300), delimiter=st.sampled_from([",", None, "auto"]),
       header=st.sampled_from(["required", "optional"]))
def test_read_table_on_any_text(folder, text, delimiter, header):
    result_or_input_error(read_table, write(folder / "t.csv", text), delimiter, header)


# ----------------------------------------------------------------------------- recipe + dataset


def _dataset(folder: Path) -> Path:
    d = folder / "ds"
    d.mkdir(exist_ok=True)
    for name, seed in (("imu.csv", imu_seed), ("gnss.csv", gnss_seed),
                       ("heading.csv", heading_seed), ("reference.csv", reference_seed)):
        write(d / name, seed())
    return d


def test_recipe_seed_loads(folder):
    d = _dataset(folder)
    ds = load_dataset(load_recipe(write(d / "recipe.toml", RECIPE_SEED)))
    assert ds.imu.t.size == 60


@fuzz_settings(80)
@given(edit_list=edits)
def test_mutated_recipe_gives_result_or_input_error(folder, edit_list):
    d = _dataset(folder)
    path = write(d / "m-recipe.toml", mutate(RECIPE_SEED, edit_list))
    recipe = result_or_input_error(load_recipe, path)
    if not isinstance(recipe, Exception):
        result_or_input_error(load_dataset, recipe)


@fuzz_settings(30)
@given(text=st.text(max_size=200))
def test_read_toml_on_any_text(folder, text):
    result_or_input_error(read_toml, write(folder / "any.toml", text))


def test_scenario_seed_loads():
    from gmis.simulate.scenario import default_scenario_path, load_scenario
    assert load_scenario(default_scenario_path())


@fuzz_settings(60)
@given(edit_list=edits)
def test_mutated_scenario_gives_result_or_input_error(folder, edit_list):
    from gmis.simulate.scenario import default_scenario_path, load_scenario
    seed = Path(default_scenario_path()).read_text()
    path = write(folder / "scenario.toml", mutate(seed, edit_list))
    result_or_input_error(load_scenario, path)


# ----------------------------------------------------------------------------- RINEX / SP3



def _seed_text(path: Path) -> str:
    return require(path).read_text(errors="replace")


def _rinex_reader(kind):
    from gnss.rinex import read_nav, read_obs
    if kind == "obs":
        return lambda p: read_obs(p, use_cache=False)
    return lambda p: read_nav(p, use_cache=False)


RINEX_SEEDS = {
    "obs2": ("obs", CORPUS / "minimal2.10o"),
    "obs2-demo": ("obs", CORPUS / "demo.10o"),
    "obs3": ("obs", CORPUS / "demo3.10o"),
    "nav2": ("nav", CORPUS / "demo.10n"),
    "nav3": ("nav", CORPUS / "demo_nav3.17n"),
}


@pytest.mark.parametrize("name", sorted(RINEX_SEEDS))
def test_rinex_seed_reads(folder, name):
    kind, path = RINEX_SEEDS[name]
    seed = _seed_text(path)
    out = _rinex_reader(kind)(write(folder / f"seed-{name}{path.suffix}", seed))
    assert out is not None


@pytest.mark.parametrize("name", sorted(RINEX_SEEDS))
@fuzz_settings(25, shrink=False)
@given(edit_list=edits)
def test_mutated_rinex_gives_result_or_input_error(folder, name, edit_list):
    kind, path = RINEX_SEEDS[name]
    text = mutate(_seed_text(path), edit_list)
    result_or_input_error(_rinex_reader(kind), write(folder / f"m-{name}{path.suffix}", text))


def test_known_rinex3_deleted_lines(folder):
    """Found by the fuzz test (GMIS_FUZZ_EXAMPLES=300): two observation lines deleted."""
    from gnss.rinex import read_obs
    text = mutate(_seed_text(CORPUS / "demo3.10o"), [("delete_line", 0.75),
                                                      ("delete_line", 0.875)])
    result_or_input_error(lambda p: read_obs(p, use_cache=False),
                          write(folder / "known-rinex3.10o", text))


def test_known_sp3_garbled_epoch_time(folder):
    """Found by the fuzz test (GMIS_FUZZ_EXAMPLES=300): one character replaced by '0'."""
    from gnss.sp3 import read_sp3
    text = mutate(_seed_text(CORPUS / "example1.sp3a"), [("replace", 0.828125, "0")])
    result_or_input_error(read_sp3, write(folder / "known.sp3", text))


@fuzz_settings(25, shrink=False)
@given(edit_list=edits)
def test_mutated_sp3_gives_result_or_input_error(folder, edit_list):
    from gnss.sp3 import read_sp3
    text = mutate(_seed_text(CORPUS / "example1.sp3a"), edit_list)
    result_or_input_error(read_sp3, write(folder / "m.sp3", text))


def test_real_rtklib_pos_file_reads():
    from gnss.pos_file import read_pos
    result_or_input_error(read_pos, require(SHARED_DATA / "drive-boulder-0708" /
                                            "gnss_1934_sf.pos"))


def _pos_seed(folder: Path) -> str:
    """A .pos written by gnss.pos_file.write_pos (3 epochs), the format read_pos documents."""
    from gnss.pos_file import write_pos
    from gnss.rtk import RtkSolution
    n = 3
    sol = RtkSolution(t_gps=1.4e9 + np.arange(n), ecef=np.zeros((n, 3)),
                      llh=np.tile([0.7, -1.4, 180.0], (n, 1)), q=np.array([1, 2, 1]),
                      ratio=np.array([5.0, 1.2, 7.0]), n_sat=np.full(n, 8),
                      sigma_enu=np.full((n, 3), 0.01), ambiguities_fixed=np.zeros(n, int),
                      ref_prn=np.zeros(n, int), integers=[None] * n)
    return write_pos(folder / "seed.pos", sol).read_text()


@fuzz_settings(25, shrink=False)
@given(edit_list=edits)
def test_mutated_pos_gives_result_or_input_error(folder, edit_list):
    from gnss.pos_file import read_pos
    text = mutate(_pos_seed(folder), edit_list)
    result_or_input_error(read_pos, write(folder / "m.pos", text))


# ----------------------------------------------------------------------------- RTKLIB .tag

def _tag_seed() -> bytes:
    import struct
    head = b"TIMETAG RTKLIB demo5".ljust(60, b"\0") + struct.pack("<IId", 7, 1752003261, 0.854)
    return head + b"".join(struct.pack("<II", 10 * i, 64 * i) for i in range(40))


def _tick_csv_seed(n=40) -> str:
    return "".join(f"0.1,0.0,1.0,0.5,-0.5,0.1,{1000 + 10 * k}\n" for k in range(n))


def test_tag_and_tick_seeds_are_valid(folder):
    from gmis.readers import read_imu_tagged
    tag = folder / "seed.tag"
    tag.write_bytes(_tag_seed())
    imu = read_imu_tagged(write(folder / "tick.csv", _tick_csv_seed()), tag,
                          ImuSection(rate_hz=100.0, time_base="tag"))
    assert imu.t.size == 40


@fuzz_settings(60)
@given(cut=st.integers(0, 400), flips=st.lists(st.tuples(st.integers(0, 300),
                                                         st.integers(0, 255)), max_size=6),
       extra=st.binary(max_size=20))
def test_mutated_tag_gives_result_or_input_error(folder, cut, flips, extra):
    from gmis.readers_rtklib import read_time_tag
    raw = bytearray(_tag_seed()[:cut] if cut < 396 else _tag_seed())
    for pos, value in flips:
        if pos < len(raw):
            raw[pos] = value
    path = folder / "m.tag"
    path.write_bytes(bytes(raw) + extra)
    result_or_input_error(read_time_tag, path)


@fuzz_settings(60)
@given(edit_list=edits)
def test_mutated_tick_csv_gives_result_or_input_error(folder, edit_list):
    from gmis.readers import read_imu_tagged
    tag = folder / "seed.tag"
    tag.write_bytes(_tag_seed())
    path = write(folder / "m-tick.csv", mutate(_tick_csv_seed(), edit_list))
    result_or_input_error(read_imu_tagged, path, tag, ImuSection(rate_hz=100.0,
                                                                 time_base="tag"))
