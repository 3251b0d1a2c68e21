"""A simulated GNSS-only session for the tightly coupled filter's AR and slip tests
(`gmis rtk --tight` path, gmis.tc_gnss_only): synthetic constellation with 7 satellites
above 15°, static base, rover at 7.2 m/s, 1 Hz, RINEX written and read back."""

from __future__ import annotations

import numpy as np

from gmis.earth import geodetic_to_ecef
from gmis.simulate.raw_gnss import (
    RawGnssConfig,
    ReceiverTrack,
    SkyBlockage,
    simulate_raw_gnss,
    synthetic_gps_nav,
)
from gmis.simulate.rinex_writer import write_nav_rinex3, write_obs_rinex3
from gnss.rinex import read_nav, read_obs

T0 = 1590 * 604800.0 + 345600.0 + 5400.0     # GPS s
BASE = np.array(geodetic_to_ecef(np.deg2rad(43.77), np.deg2rad(-79.50), 170.0))
VEL = np.array([6.0, -4.0, 0.5])


def rover_track(n_ep: int) -> np.ndarray:
    t = np.arange(n_ep, dtype=float)
    return BASE + np.array([400.0, -250.0, 120.0]) + np.outer(t, VEL)


def satellites_by_elevation(n_ep: int) -> np.ndarray:
    """PRNs above 15° at the rover's first epoch, highest first."""
    nav = synthetic_gps_nav(T0 - 1800.0)
    probe = simulate_raw_gnss(np.array([T0]), [ReceiverTrack("rover", rover_track(1), None)],
                              nav, seed=11).receivers["rover"]
    el = np.degrees(probe.elevation[0])
    up = np.isfinite(el) & (el > 15.0)
    return probe.prn[up][np.argsort(-el[up])]


def simulate_session(folder, n_ep: int, config: RawGnssConfig | None = None,
                     lowest_l1_bias_cycles: float = 0.0):
    """(sim, {"base", "rover"}: ObsData, nav). lowest_l1_bias_cycles: added to the rover L1
    of the lowest satellite (e.g. an unresolved half cycle)."""
    t = T0 + np.arange(n_ep, dtype=float)
    rcv = [ReceiverTrack("base", BASE, None, vehicle=False),
           ReceiverTrack("rover", rover_track(n_ep), np.broadcast_to(VEL, (n_ep, 3)))]
    nav = synthetic_gps_nav(T0 - 1800.0)
    sim = simulate_raw_gnss(t, rcv, nav, config or RawGnssConfig(), seed=11)
    rv = sim.receivers["rover"]
    if lowest_l1_bias_cycles:
        low = int(np.flatnonzero(rv.prn == satellites_by_elevation(n_ep)[-1])[0])
        rv.obs["L1"][:, low] += lowest_l1_bias_cycles
    write_nav_rinex3(folder / "syn.nav", nav)
    for name, r in sim.receivers.items():
        write_obs_rinex3(folder / f"{name}.obs", r.t_gps, r.prn, r.obs, r.lli1, r.lli2,
                         r.antenna_ecef[0], name.upper())
    obs = {n: read_obs(folder / f"{n}.obs") for n in ("base", "rover")}
    return sim, obs, read_nav(folder / "syn.nav")


def five_satellite_stretch(folder, n_ep=180):
    """(sim, obs, nav, biased prn): 5 highest satellites only during t0 + 60 … 120 s and a
    +0.5 cycle rover L1 bias on the 5th highest (in view throughout)."""
    cfg = RawGnssConfig(blockages=[SkyBlockage(T0 + 60, T0 + 120, highest_n=5)])
    sim, obs, nav = simulate_session(folder, n_ep, cfg)
    biased = int(satellites_by_elevation(n_ep)[4])
    col = int(np.flatnonzero(obs["rover"].prn == biased)[0])
    obs["rover"].L1[:, col] += 0.5
    return sim, obs, nav, biased


def without_slip_flags(prepare):
    """``prepare`` (gmis.tc_gnss_only.prepare_tc_epochs) with every epoch's cycle-slip flags
    cleared, as if the RINEX-level detectors had missed every slip."""
    def prepare_without_flags(*args, **kwargs):
        epochs = prepare(*args, **kwargs)
        for ep in epochs:
            ep.slip[:] = False
        return epochs
    return prepare_without_flags


def wrong_integers(sim, sol, skip=()):
    """(wrong, checked) DD integers of the fixed epochs against the simulated truth; skip:
    (prn, frequency) keys not checked."""
    prn = list(sim.prn)
    sd = {f: getattr(sim.receivers["rover"], f"ambiguity_l{f}")
          - getattr(sim.receivers["base"], f"ambiguity_l{f}") for f in (1, 2)}
    rec = sol.tc_records
    wrong = checked = 0
    for g, ints in zip(np.flatnonzero(sol.fixed), rec.integers):
        e = int(np.argmin(np.abs(sim.t_gps - sol.t_gps[g])))
        for (p, f), v in ints.items():
            if (p, f) in skip:
                continue
            truth = sd[f][e, prn.index(p)] - sd[f][e, prn.index(rec.ref_prn[g])]
            wrong += round(truth) != v
            checked += 1
    return wrong, checked
