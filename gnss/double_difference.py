"""Between-receiver, between-satellite double differences (DD) and their covariance.

Convention (001 eq. 5.1.7): ∇ΔL_AB^jk = [L_B^k − L_A^k] − [L_B^j − L_A^j], A = base (known
coordinates), B = rover, j = reference satellite, k = the other satellites. DD observables:
code C1/C2 (m), phase L1/L2 (cycles; ×λ for m), Doppler D1/D2 (Hz; range rate = −λ·D m/s).

Short-baseline assumption (< 10 km, 001 §5.1.2.2): satellite clock, ionospheric and
tropospheric delays cancel in the DD and are not modelled; receiver clocks cancel; the
satellite position is computed for each receiver at its own transmission time (from its own
pseudorange) so the receiver clock offsets do not leak into the geometry.

Geometry: computed DD range ∇Δρ = (ρ_B^k − ρ_A^k) − (ρ_B^j − ρ_A^j) with ρ = |r^s − r_rcv|
(Sagnac-corrected satellite positions). Design row for the rover position r_B (ECEF):
∂∇Δρ/∂r_B = −(e_B^k − e_B^j), e = unit line-of-sight vector rover → satellite.

Covariance (001 eq. 5.1.8-5.1.11): undifferenced σ²_A,k = σ90² m_A,k, m = 1 + 1/sin²β
(5.1.8, Takasu 2013). With single differences sd_k = L_B^k − L_A^k (σ²_sd,k = σ²_A,k +
σ²_B,k) and DD = D·sd, D = [I | −1] in reference-column form, R = D diag(σ²_sd) Dᵀ =
σ90² M with M_kk = m_sd,k + m_sd,j and M_kl = m_sd,j (5.1.9/5.1.10). One σ90 per
observable type (code, phase, Doppler) gives the block-diagonal 5.1.11. A subset of DD rows
(e.g. dropping NaN observables) keeps the matching rows/columns of M.

Reference satellite (hysteresis): the current reference is kept while it is observed by both
receivers with L1 phase and its rover elevation stays ≥ mask + margin (default 15° + 5°);
otherwise the highest-elevation eligible satellite becomes the reference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gnss.constants import WAVELENGTH_L1, WAVELENGTH_L2
from gnss.ephemeris import satellite_states_at_reception
from gnss.epoch_matching import DEFAULT_TOLERANCE_S, match_epochs
from gnss.geodesy import ecef_to_geodetic
from gnss.rinex import NavData, ObsData

DD_OBSERVABLES = ("C1", "C2", "L1", "L2", "D1", "D2")


def elevation_cofactor(elevation):
    """m = 1 + 1/sin²β (001 eq. 5.1.8), elevation β in rad."""
    s = np.sin(np.asarray(elevation, dtype=float))
    return 1.0 + 1.0 / (s * s)


def sd_to_dd_matrix(n_sats: int, ref_index: int) -> np.ndarray:
    """D (n−1, n): DD_k = SD_k − SD_ref for every k ≠ ref, rows in satellite order."""
    others = [k for k in range(n_sats) if k != ref_index]
    d = np.zeros((n_sats - 1, n_sats))
    d[np.arange(n_sats - 1), others] = 1.0
    d[:, ref_index] = -1.0
    return d


def between_satellites(sd, others, ref):
    """DD from single differences (001 eq. 5.1.7): sd[others] − sd[ref], sd (n,) one value
    per satellite (rover − base), others index array, ref the reference's index; the one
    SD → DD subtraction of gnss (double_difference_epoch) and gmis.tc_filter."""
    return sd[others] - sd[ref]


def dd_cofactor(m_sd: np.ndarray, m_sd_ref: float) -> np.ndarray:
    """M of 001 eq. 5.1.10: diag(m_sd,k) + m_sd,ref·11ᵀ for the non-reference satellites,
    m_sd = m_A + m_B (single-difference cofactors)."""
    m_sd = np.asarray(m_sd, dtype=float)
    return np.diag(m_sd) + m_sd_ref


def dd_covariance(sigma90: float, m_base, m_rover, ref_index: int) -> np.ndarray:
    """σ90²·M (001 eq. 5.1.9/5.1.10) from undifferenced cofactors m_base, m_rover (n,)
    of all satellites including the reference at ref_index."""
    m_sd = np.asarray(m_base, float) + np.asarray(m_rover, float)
    others = np.arange(m_sd.size) != ref_index
    return sigma90 ** 2 * dd_cofactor(m_sd[others], m_sd[ref_index])


def select_reference_satellite(prn, elevation, eligible=None, current_ref: int = -1,
                               elevation_mask_deg: float = 15.0,
                               margin_deg: float = 5.0) -> int:
    """Reference PRN with hysteresis (see module doc); −1 if no satellite is eligible."""
    prn = np.asarray(prn)
    el = np.asarray(elevation, dtype=float)
    ok = np.isfinite(el) if eligible is None else (np.asarray(eligible) & np.isfinite(el))
    if not ok.any():
        return -1
    hit = np.flatnonzero((prn == current_ref) & ok)
    if current_ref >= 0 and hit.size and \
            el[hit[0]] >= np.deg2rad(elevation_mask_deg + margin_deg):
        return int(current_ref)
    cand = np.flatnonzero(ok)
    return int(prn[cand[np.argmax(el[cand])]])


@dataclass
class DDEpoch:
    """DD at one epoch, one row per non-reference satellite (m rows).

    prn (m,), ref_prn, observables dict name → (m,) for C1, C2 (m), L1, L2 (cycles),
    D1, D2 (Hz) — NaN where either receiver lacks the observable; computed_range (m,) DD
    geometric range from the given positions (m); design (m,3) ∂∇Δρ/∂r_rover;
    elevation_base/rover (m,) rad and ref_elevation_base/rover; m_sd (m,), m_sd_ref: SD
    cofactors; lli_l1/lli_l2 (m,) bool: loss-of-lock flag on k or ref at either receiver."""

    t_gps: float
    ref_prn: int
    prn: np.ndarray
    observables: dict
    computed_range: np.ndarray
    design: np.ndarray
    elevation_base: np.ndarray
    elevation_rover: np.ndarray
    ref_elevation_base: float
    ref_elevation_rover: float
    m_sd: np.ndarray
    m_sd_ref: float
    lli_l1: np.ndarray
    lli_l2: np.ndarray

    @property
    def cofactor(self) -> np.ndarray:
        """M (m, m) of 001 eq. 5.1.10."""
        return dd_cofactor(self.m_sd, self.m_sd_ref)

    def covariance(self, sigma90: float) -> np.ndarray:
        """σ90²·M (001 eq. 5.1.10); σ90 in the unit of the observable."""
        return sigma90 ** 2 * self.cofactor

    @property
    def phase_l1_m(self) -> np.ndarray:
        return WAVELENGTH_L1 * self.observables["L1"]

    @property
    def phase_l2_m(self) -> np.ndarray:
        return WAVELENGTH_L2 * self.observables["L2"]

    @property
    def range_rate_l1_m_s(self) -> np.ndarray:
        """DD range rate from L1 Doppler: −λ1·∇ΔD1 (m/s)."""
        return -WAVELENGTH_L1 * self.observables["D1"]

    @property
    def range_rate_l2_m_s(self) -> np.ndarray:
        return -WAVELENGTH_L2 * self.observables["D2"]


def geodetic_up(ecef) -> np.ndarray:
    """Unit ellipsoid normal (3,) at an ECEF point (m): the local "up" of elevations
    (the geocentric direction r/|r| differs from it by up to ~0.19° at 45° latitude)."""
    lat, lon, _ = ecef_to_geodetic(*np.asarray(ecef, float))
    return np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])


def _los_and_elevation(receiver, sat_pos):
    """Unit LOS (n,3), range (n,) and elevation (n,) rad; receiver (3,) or (n,3)."""
    receiver = np.asarray(receiver, float)
    rcv = np.broadcast_to(receiver, sat_pos.shape)
    d = sat_pos - rcv
    rho = np.linalg.norm(d, axis=1)
    los = d / rho[:, None]
    if receiver.ndim == 1:                   # one receiver position: one "up" for all rows
        up = np.broadcast_to(geodetic_up(receiver), sat_pos.shape)
    else:
        up = np.empty_like(rcv)
        for uniq in np.unique(rcv, axis=0):
            rows = np.all(rcv == uniq, axis=1)
            up[rows] = geodetic_up(uniq)
    el = np.arcsin(np.clip(np.sum(los * up, axis=1), -1.0, 1.0))
    return los, rho, el


def double_difference_epoch(t_gps: float, prn, base: dict, rover: dict, sat_pos_base,
                            sat_pos_rover, base_ecef, rover_ecef, current_ref: int = -1,
                            elevation_mask_deg: float = 15.0,
                            ref_margin_deg: float = 5.0) -> DDEpoch | None:
    """Form the DD of one epoch.

    prn (n,) satellites; base/rover: dict name → (n,) for DD_OBSERVABLES (missing keys =
    NaN) plus optional "LLI1"/"LLI2" ints; sat_pos_base/rover (n,3) Sagnac-corrected ECEF
    satellite positions for each receiver (m). A satellite takes part if both receivers
    have its C1 and a position and it is above the mask at both sites. Returns None when
    fewer than two satellites qualify."""
    prn = np.asarray(prn, dtype=np.int64)
    n = prn.size

    def get(site: dict, name: str) -> np.ndarray:
        return np.asarray(site.get(name, np.full(n, np.nan)), dtype=float)

    sat_b = np.asarray(sat_pos_base, float)
    sat_r = np.asarray(sat_pos_rover, float)
    _, rho_a, el_a = _los_and_elevation(base_ecef, sat_b)
    los_b, rho_b, el_b = _los_and_elevation(rover_ecef, sat_r)
    mask = np.deg2rad(elevation_mask_deg)
    ok = (np.isfinite(get(base, "C1")) & np.isfinite(get(rover, "C1")) & np.isfinite(rho_a)
          & np.isfinite(rho_b) & (el_a >= mask) & (el_b >= mask))
    if ok.sum() < 2:
        return None
    has_phase = ok & np.isfinite(get(base, "L1")) & np.isfinite(get(rover, "L1"))
    ref = select_reference_satellite(prn, el_b, has_phase if has_phase.any() else ok,
                                     current_ref, elevation_mask_deg, ref_margin_deg)
    j = int(np.flatnonzero(prn == ref)[0])
    k = np.flatnonzero(ok & (prn != ref))
    obs = {}
    for name in DD_OBSERVABLES:
        sd = get(rover, name) - get(base, name)
        obs[name] = between_satellites(sd, k, j)
    rng_sd = rho_b - rho_a
    lli = {}
    for name in ("LLI1", "LLI2"):
        flag = (np.asarray(base.get(name, np.zeros(n)), dtype=np.int64) & 1) | \
               (np.asarray(rover.get(name, np.zeros(n)), dtype=np.int64) & 1)
        lli[name] = (flag[k] | flag[j]).astype(bool)
    m_sd = elevation_cofactor(el_a) + elevation_cofactor(el_b)
    return DDEpoch(t_gps=float(t_gps), ref_prn=int(ref), prn=prn[k], observables=obs,
                   computed_range=rng_sd[k] - rng_sd[j], design=-(los_b[k] - los_b[j]),
                   elevation_base=el_a[k], elevation_rover=el_b[k],
                   ref_elevation_base=float(el_a[j]), ref_elevation_rover=float(el_b[j]),
                   m_sd=m_sd[k], m_sd_ref=float(m_sd[j]), lli_l1=lli["LLI1"],
                   lli_l2=lli["LLI2"])


@dataclass
class DDSession:
    """DD of a whole session, packed: epoch i owns rows start[i]:start[i+1] of the flat
    (n_dd,) arrays. t_gps/ref_prn/ref_elevation_rover/m_sd_ref (n_ep,) (ref_prn −1 and
    no rows when an epoch has < 2 usable satellites); prn, epoch, computed_range, m_sd,
    elevation_base/rover, lli_l1/lli_l2 (n_dd,); design (n_dd,3); observables name →
    (n_dd,) as in DDEpoch."""

    t_gps: np.ndarray
    ref_prn: np.ndarray
    start: np.ndarray
    epoch_index: np.ndarray
    prn: np.ndarray
    observables: dict
    computed_range: np.ndarray
    design: np.ndarray
    elevation_base: np.ndarray
    elevation_rover: np.ndarray
    ref_elevation_base: np.ndarray
    ref_elevation_rover: np.ndarray
    m_sd: np.ndarray
    m_sd_ref: np.ndarray
    lli_l1: np.ndarray
    lli_l2: np.ndarray

    @property
    def n_epochs(self) -> int:
        return self.t_gps.size

    def epoch(self, i: int) -> DDEpoch | None:
        """Unpack epoch i (None when it has no DD)."""
        a, b = self.start[i], self.start[i + 1]
        if self.ref_prn[i] < 0:
            return None
        return DDEpoch(t_gps=float(self.t_gps[i]), ref_prn=int(self.ref_prn[i]),
                       prn=self.prn[a:b], observables={k: v[a:b] for k, v in
                                                       self.observables.items()},
                       computed_range=self.computed_range[a:b], design=self.design[a:b],
                       elevation_base=self.elevation_base[a:b],
                       elevation_rover=self.elevation_rover[a:b],
                       ref_elevation_base=float(self.ref_elevation_base[i]),
                       ref_elevation_rover=float(self.ref_elevation_rover[i]),
                       m_sd=self.m_sd[a:b], m_sd_ref=float(self.m_sd_ref[i]),
                       lli_l1=self.lli_l1[a:b], lli_l2=self.lli_l2[a:b])

    def cofactor(self, i: int) -> np.ndarray:
        a, b = self.start[i], self.start[i + 1]
        return dd_cofactor(self.m_sd[a:b], self.m_sd_ref[i])


def _site_states(nav, obs: ObsData, ep_idx, col_idx, prn, receiver_ecef):
    """Sagnac-corrected satellite positions (n_ep, n_sat, 3) for one receiver at the
    transmission times of its own C1 code (NaN where C1 is missing)."""
    n_ep, n_sat = ep_idx.size, prn.size
    pos = np.full((n_ep, n_sat, 3), np.nan)
    code = np.full((n_ep, n_sat), np.nan)
    have = col_idx >= 0
    code[:, have] = obs.C1[np.ix_(ep_idx, col_idx[have])]
    e, s = np.nonzero(np.isfinite(code))
    if e.size:
        rcv = np.asarray(receiver_ecef, float)
        rcv_rows = rcv[e] if rcv.ndim == 2 else rcv
        st, _, _ = satellite_states_at_reception(nav, prn[s], obs.t_gps[ep_idx][e],
                                                 code[e, s], rcv_rows)
        pos[e, s] = st.position
    return pos


def form_double_differences(base: ObsData, rover: ObsData, nav: NavData, base_ecef,
                            rover_ecef, elevation_mask_deg: float = 15.0,
                            ref_margin_deg: float = 5.0,
                            time_tolerance_s: float = DEFAULT_TOLERANCE_S) -> DDSession:
    """DD for all epochs common to base and rover (time tags within time_tolerance_s;
    receivers that do not steer their clock tag epochs a few ms off the nominal second, so
    the default is RTKLIB's 25 ms; each receiver's satellite positions use its own
    transmission times, so the tag difference does not bias the DD geometry).

    base_ecef: (3,) fixed base, or (n_base_epochs, 3) for a moving base (dual-antenna
    heading: the primary antenna is the base).
    rover_ecef: (3,) or (n_rover_epochs, 3) approximate/known rover positions (used for
    the computed range, design rows, elevations and Sagnac). Satellite states are computed
    vectorised over the whole session; the reference hysteresis runs epoch by epoch."""
    base_ecef = np.asarray(base_ecef, float)
    rover_ecef = np.asarray(rover_ecef, float)
    best = match_epochs(base.t_gps, rover.t_gps, time_tolerance_s)
    ir = np.flatnonzero(best >= 0)
    ib = best[ir]
    prn = np.union1d(base.prn, rover.prn)
    col_b = np.array([base.sat_index(p) for p in prn])
    col_r = np.array([rover.sat_index(p) for p in prn])
    rover_rows = rover_ecef[ir] if rover_ecef.ndim == 2 else rover_ecef
    base_rows = base_ecef[ib] if base_ecef.ndim == 2 else base_ecef
    pos_b = _site_states(nav, base, ib, col_b, prn, base_rows)
    pos_r = _site_states(nav, rover, ir, col_r, prn, rover_rows)

    def table(obs, name, ep, col):
        """(epochs, prn) of one observable in the common satellite order (NaN: absent)."""
        out = np.full((ep.size, prn.size), np.nan)
        have = col >= 0
        out[:, have] = getattr(obs, name)[np.ix_(ep, col[have])]
        return out

    names = DD_OBSERVABLES + ("LLI1", "LLI2")
    tab_b = {k: table(base, k, ib, col_b) for k in names}
    tab_r = {k: table(rover, k, ir, col_r) for k in names}
    for tab in (tab_b, tab_r):
        for k in ("LLI1", "LLI2"):
            tab[k] = np.where(np.isfinite(tab[k]), tab[k], 0).astype(np.int64)

    rows = {k: [] for k in ("prn", "epoch", "rng", "design", "el_b", "el_r", "m_sd",
                            "lli1", "lli2")}
    obs_rows = {k: [] for k in DD_OBSERVABLES}
    ref_prn = np.full(ir.size, -1, dtype=np.int64)
    ref_el_b = np.full(ir.size, np.nan)
    ref_el_r = np.full(ir.size, np.nan)
    m_ref = np.full(ir.size, np.nan)
    start = np.zeros(ir.size + 1, dtype=np.int64)
    current = -1
    for i in range(ir.size):
        site_b = {k: tab_b[k][i] for k in names}
        site_r = {k: tab_r[k][i] for k in names}
        rv = rover_ecef[ir[i]] if rover_ecef.ndim == 2 else rover_ecef
        bv = base_ecef[ib[i]] if base_ecef.ndim == 2 else base_ecef
        dd = double_difference_epoch(rover.t_gps[ir[i]], prn, site_b, site_r, pos_b[i],
                                     pos_r[i], bv, rv, current, elevation_mask_deg,
                                     ref_margin_deg)
        start[i + 1] = start[i]
        if dd is None:
            continue
        current = dd.ref_prn
        ref_prn[i], ref_el_b[i], ref_el_r[i], m_ref[i] = (dd.ref_prn, dd.ref_elevation_base,
                                                          dd.ref_elevation_rover, dd.m_sd_ref)
        start[i + 1] = start[i] + dd.prn.size
        rows["prn"].append(dd.prn)
        rows["epoch"].append(np.full(dd.prn.size, i))
        rows["rng"].append(dd.computed_range)
        rows["design"].append(dd.design)
        rows["el_b"].append(dd.elevation_base)
        rows["el_r"].append(dd.elevation_rover)
        rows["m_sd"].append(dd.m_sd)
        rows["lli1"].append(dd.lli_l1)
        rows["lli2"].append(dd.lli_l2)
        for k in DD_OBSERVABLES:
            obs_rows[k].append(dd.observables[k])

    def cat(lst, shape=(0,), dtype=float):
        return np.concatenate(lst) if lst else np.zeros(shape, dtype=dtype)

    return DDSession(
        t_gps=rover.t_gps[ir].copy(), ref_prn=ref_prn, start=start,
        epoch_index=cat(rows["epoch"], dtype=np.int64), prn=cat(rows["prn"], dtype=np.int64),
        observables={k: cat(v) for k, v in obs_rows.items()},
        computed_range=cat(rows["rng"]), design=cat(rows["design"], (0, 3)),
        elevation_base=cat(rows["el_b"]), elevation_rover=cat(rows["el_r"]),
        ref_elevation_base=ref_el_b, ref_elevation_rover=ref_el_r, m_sd=cat(rows["m_sd"]),
        m_sd_ref=m_ref, lli_l1=cat(rows["lli1"], dtype=bool),
        lli_l2=cat(rows["lli2"], dtype=bool))
