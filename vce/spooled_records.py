"""The VCE job's filter records on disk (docs/DESIGN.md "Bounded memory").

Every iteration of vce.tune runs the GMIKF with a sink (gmis.run_filter.GmikfRunner) that
spools, per variance component, only the record columns its estimate reads: v_z, r_z,
R_ii and the outlier flags of a measurement slot, v_w and r_w of a process-noise axis,
one ``.npy`` file each (gmis.record_spool). :class:`SpooledRecords` stands in for
FilterRecords in vce.estimate: ``rec.vz[:, idx]`` reads the columns of idx only, so a
component's estimate holds its own columns and nothing else. The standardized residuals
kept for the report are written to the same folder (:func:`spool_residuals`) and read
back by the job's writer one component at a time.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gmis.record_spool import ColumnSpool

MEASUREMENT_COLUMNS = {"vz": np.float64, "rz": np.float64, "rvar": np.float64,
                       "rejected": np.int8}
PROCESS_COLUMNS = {"vw": np.float64, "rw": np.float64}


class SlotColumns:
    """``rec.<name>`` of a spooled run: indexing [:, idx] reads the columns idx."""

    def __init__(self, spool: ColumnSpool, name: str):
        self.spool, self.name = spool, name

    def __getitem__(self, key):
        rows, cols = key
        if rows != slice(None):
            raise IndexError("spooled records are read by whole columns: rec.x[:, idx]")
        if np.isscalar(cols):
            return self.spool.read(f"{self.name}_{cols}")
        cols = list(cols)
        _, dt = self.spool.columns[f"{self.name}_{cols[0]}"]
        # column-major, as numpy lays out rec.x[:, idx] of a whole array: the sums of the
        # estimates then run in the same order (a C-ordered copy differs in the last bit)
        out = np.empty((self.spool.rows, len(cols)), dtype=dt, order="F")
        for j, i in enumerate(cols):
            out[:, j] = self.spool.read(f"{self.name}_{i}")
        return out


class SpooledRecords:
    """The records vce.estimate reads, spooled (module docstring), with the epoch times,
    the stationary flags and the accumulated Helmert sums in memory."""

    def __init__(self, spool, t, still, helmert_s, helmert_totals, helmert_trunc=None):
        self.spool, self.t, self.still = spool, t, still
        self.n_epochs = spool.rows
        self.helmert_s, self.helmert_totals = helmert_s, helmert_totals
        self.helmert_trunc = helmert_trunc
        for name in (*MEASUREMENT_COLUMNS, *PROCESS_COLUMNS):
            setattr(self, name, SlotColumns(spool, name))

    def block(self, comp, e0: int, e1: int):
        """vce.estimate.component_columns of epochs [e0, e1): (v, r, R_ii, rejected) or
        (v_w, r_w, None, None), each (e1 − e0, k) column-major as the whole columns."""
        names = ("vz", "rz", "rvar", "rejected") if comp.kind == "measurement" else \
            ("vw", "rw")
        out = []
        for name in names:
            cols = list(comp.index)
            _, dt = self.spool.columns[f"{name}_{cols[0]}"]
            a = np.empty((min(e1, self.n_epochs) - e0, len(cols)), dtype=dt, order="F")
            for j, i in enumerate(cols):
                a[:, j] = self.spool.read(f"{name}_{i}", e0, e1)
            out.append(a)
        return (*out, None, None) if len(out) == 2 else tuple(out)


def spooled_run(run, comps, n_epochs: int, folder) -> SpooledRecords:
    """Run the filter through ``run(sink=...)`` (e.g. gmis.run_preparation.run_prepared
    with its other arguments bound) and spool the columns of the components ``comps``."""
    slots = sorted({i for c in comps if c.kind == "measurement" for i in c.index})
    axes = sorted({i for c in comps if c.kind == "process" for i in c.index})
    columns = {f"{name}_{i}": ((), dt) for name, dt in MEASUREMENT_COLUMNS.items()
               for i in slots}
    columns.update({f"{name}_{i}": ((), dt) for name, dt in PROCESS_COLUMNS.items()
                    for i in axes})
    spool = ColumnSpool(folder, n_epochs, columns)

    def sink(e0, rec):
        blocks = {f"{name}_{i}": getattr(rec, name)[:, i] for name in MEASUREMENT_COLUMNS
                  for i in slots}
        blocks.update({f"{name}_{i}": getattr(rec, name)[:, i] for name in PROCESS_COLUMNS
                       for i in axes})
        spool.append(**blocks)

    last = run(sink=sink)
    spool.close()
    return SpooledRecords(spool, last.t, last.still, last.helmert_s, last.helmert_totals,
                          last.helmert_trunc)


class SpooledPair:
    """(t, w) of one component's standardized residuals, stored as two .npy files and
    loaded when unpacked (``t, w = pair``)."""

    def __init__(self, t_path: Path, w_path: Path):
        self.paths = (Path(t_path), Path(w_path))

    def __iter__(self):
        return (np.load(p) for p in self.paths)


def spool_component_residuals(rec, comps, q_var, still, tc_rec, folder, label: str) -> dict:
    """spool_residuals of every component's standardized residuals
    (vce.estimate.standardized_residuals); from SpooledRecords written block by block
    (vce.blockwise.standardized_residual_files), never a whole component in memory."""
    from vce.estimate import standardized_residuals

    if not isinstance(rec, SpooledRecords):
        return spool_residuals(((c.name, standardized_residuals(rec, c, q_var, still, tc_rec))
                                for c in comps), folder, label)
    from vce.blockwise import standardized_residual_files

    folder = Path(folder)
    out = {}
    for i, c in enumerate(comps):
        paths = folder / f"{label}-{i}-t.npy", folder / f"{label}-{i}-w.npy"
        if c.kind == "dd":
            t, w = standardized_residuals(rec, c, q_var, still, tc_rec)
            np.save(paths[0], t)
            np.save(paths[1], w)
        else:
            standardized_residual_files(rec, c, q_var, still, *paths)
        out[c.name] = SpooledPair(*paths)
    return out


def spool_residuals(items, folder, label: str) -> dict:
    """(component, (t, w)) pairs (an iterable: one component in memory at a time) →
    {component: SpooledPair} written to folder/<label>-<i>-*.npy."""
    folder = Path(folder)
    out = {}
    for i, (name, (t, w)) in enumerate(items):
        paths = folder / f"{label}-{i}-t.npy", folder / f"{label}-{i}-w.npy"
        np.save(paths[0], t)
        np.save(paths[1], w)
        out[name] = SpooledPair(*paths)
    return out


__all__ = ["SlotColumns", "SpooledPair", "SpooledRecords", "spool_component_residuals",
           "spool_residuals", "spooled_run"]
