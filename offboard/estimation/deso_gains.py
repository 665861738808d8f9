"""The DESO gain check (Departure 7): per eigen-channel and for the sampled network loop.

:func:`gain_report` checks the gains per eigen-channel of the observer's Laplacian
(``s³ + β1λ s² + β2λ s + β3λ`` Hurwitz ⇔ β1β2λ > β3) and the *sampled* loop of every
follower's observer by the spectral radius of its one-period error transition, with
post-update publishing and with a one-step stale exchange (:mod:`offboard.estimation.deso`).

The transitions are sparse (a block per follower and per graph edge), and the spectral
radius of a large one is found by ARPACK: a dense eigenvalue problem costs O(N³) and
took 6.4 s for 125 agents, in every daemon at start-up (each prints the report).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np
from scipy import sparse
from scipy.linalg import expm
from scipy.sparse.linalg import ArpackNoConvergence, eigs

from offboard.estimation.bearing import Formation, formation_from_scenario
from offboard.estimation.deso import _cont_matrix, observer_weights
from swarm_common.memo import ContentMemo
from swarm_common.scenario.schema import ObserverConfig
from swarm_common.scenario.spec import Scenario

log = logging.getLogger(__name__)

DENSE_MAX = 256  # matrix order up to which every eigenvalue is computed (numpy, dense)
ARPACK_K = 6  # eigenvalues of largest modulus asked of ARPACK (clusters near the top)
ARPACK_NCV = 40  # its Lanczos/Arnoldi basis size
# its restarts before the dense fallback: the generated grids and spheres converge in far
# fewer; a ring's loops, with clusters of eigenvalues at the top, ran scipy's 20 n restarts
# without converging, 10-40 s a loop (a 128-agent ring took 256 s to generate)
ARPACK_MAXITER = 1000
# the order up to which a loop ARPACK did not settle is solved dense (O(n³) time, 16 n²
# bytes: about 10 s and 150 MB here). Above it the radius is not computed (NaN) and the
# check says so: a 2,000-agent grid with 4 leaders has loops of order 17,964 and 35,928,
# whose dense solves would take hours and 20 GB
DENSE_FALLBACK_MAX = 3000
# channels sampled across [λ_min, λ_max] when a large formation has only the ends of its
# spectrum (swarm_common.scenario.spectra.spectrum): geometric, both ends exact
CHANNEL_SAMPLES = 512


@dataclass
class GainReport:
    """Numbers of the DESO gain check (Departure 7); ``lines()`` for printing at start-up."""

    beta: tuple[float, ...]
    dt: float
    substeps: int
    lambda_ff: np.ndarray
    margin: np.ndarray  # β1 β2 λ − β3 per channel (>0 ⇔ Hurwitz)
    max_real_pole: float  # slowest continuous pole over all channels (<0)
    fastest_bandwidth: float  # β1 λ_max  (rad/s)
    euler_number: float  # δ β1 λ_max with δ = dt/substeps (explicit Euler needs < 2)
    rho_post_update: float  # spectral radius, exact sub-steps, post-update exchange
    rho_stale: float  # same with neighbours' estimates one period stale
    rho_euler_post: float  # explicit Euler sub-steps, post-update exchange
    rho_single_euler_stale: float  # one Euler step per period, one-step stale (naive)
    paper_condition: bool  # β2 > β1 + β3/λ_min (paper §3)
    kappa: tuple[float, ...] = (0.0, 0.0)  # velocity-innovation gains κ2, κ3
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """Every channel Hurwitz and the sampled loop's spectral radius below 1 (a radius
        that could not be computed, NaN, is not ok)."""
        return bool(self.max_real_pole < 0.0 and self.rho_post_update < 1.0)

    def problem(self) -> str | None:
        """One line naming the observer keys when the check fails (``ok`` is False): a
        channel not Hurwitz, or a sampled loop of spectral radius >= 1; else None. The
        loader-level rule (issue 42): an error, or a warning with --allow-infeasible,
        never an INFO line."""
        if self.ok:
            return None
        b, k = self.beta, self.kappa
        keys = (f"observer.beta = [{b[0]:g}, {b[1]:g}, {b[2]:g}] (velocity_gain = "
                f"[{k[0]:g}, {k[1]:g}], substeps = {self.substeps}, dt = {self.dt:g} s)")
        span = (f"lambda(observer Laplacian) in [{self.lambda_ff[0]:.3f}, "
                f"{self.lambda_ff[-1]:.3f}]")
        if self.max_real_pole >= 0.0:
            return (f"{keys}: the DESO is unstable on this graph: its slowest channel pole "
                    f"is {self.max_real_pole:.3f} 1/s >= 0 ({span})")
        if math.isnan(self.rho_post_update):
            return (f"{keys}: the DESO's sampled loop could not be checked: ARPACK did not "
                    f"settle its spectral radius, and the loop is too large to solve dense "
                    f"({span}; more leaders or a denser formation.graph settle it)")
        return (f"{keys}: the DESO is unstable on this graph: its sampled loop has spectral "
                f"radius {self.rho_post_update:.4f} >= 1 ({span}; change the gains, "
                f"formation.graph or observer.leader_anchor)")

    def lines(self) -> list[str]:
        b = self.beta
        return [
            f"DESO gains beta = {b[0]:g}/{b[1]:g}/{b[2]:g}, kappa = {self.kappa[0]:g}/"
            f"{self.kappa[1]:g}, dt = {self.dt:g} s x {self.substeps} sub-steps",
            f"  lambda(observer Laplacian) in [{self.lambda_ff[0]:.3f}, {self.lambda_ff[-1]:.3f}]; "
            f"channel margin min(b1 b2 lam - b3) = {self.margin.min():.1f} "
            f"({'Hurwitz' if np.all(self.margin > 0) else 'NOT Hurwitz'} without kappa); "
            f"slowest pole {self.max_real_pole:.3f} 1/s",
            f"  paper condition b2 > b1 + b3/lam_min: {self.paper_condition}",
            f"  fastest channel b1*lam_max = {self.fastest_bandwidth:.1f} rad/s; "
            f"dt_sub*b1*lam_max = {self.euler_number:.2f} (< 2 for explicit Euler)",
            f"  sampled loop spectral radius: exact sub-steps post-update "
            f"{_radius(self.rho_post_update)}, "
            f"one-step stale {_radius(self.rho_stale)}; Euler sub-steps "
            f"{_radius(self.rho_euler_post)}; "
            f"single Euler step + stale {_radius(self.rho_single_euler_stale)}",
            f"  => {'OK' if self.ok else 'UNSTABLE'}",
        ]


def _radius(rho: float) -> str:
    """A spectral radius as the report prints it ("not computed" for NaN)."""
    return "not computed" if math.isnan(rho) else f"{rho:.4f}"


def _network_transition(
    form: Formation, beta: tuple[float, ...], dt: float, substeps: int, euler: bool,
    leader_anchor: float = 0.0, kappa: tuple[float, ...] = (0.0, 0.0),
) -> tuple[sparse.csr_matrix, sparse.csr_matrix]:
    """One-period error transition of all followers: E_{k+1} = T0 E_k + T1 E_nbr (sparse).

    E = [z̃1; z̃2; z̃3] stacked per follower (9 per follower). T1 multiplies the neighbour
    data actually used (current for post-update, previous for stale). T0 is block
    diagonal and T1 has a 9×3 pair of blocks per graph edge, so both hold O(N) entries
    (each block is written once: the same numbers as a dense accumulation).
    """
    fol = form.follower_idx
    nf = len(fol)
    pos = {a: k for k, a in enumerate(fol)}
    delta = dt / substeps
    blocks0: list[tuple[int, int, np.ndarray]] = []
    blocks1: list[tuple[int, int, np.ndarray]] = []
    for k, i in enumerate(fol):
        wts = observer_weights(form, i, leader_anchor)
        dmat = np.zeros((3, 3))
        for pij in wts.values():
            dmat += pij
        a = _cont_matrix(dmat, beta, kappa)
        m = np.eye(18) + a * delta if euler else expm(a * delta)
        mm = np.linalg.matrix_power(m, substeps)[:9, :15]
        blocks0.append((9 * k, 9 * k, mm[:, :9]))
        for j, pij in wts.items():
            if j in pos:
                c = pos[j]
                blocks1.append((9 * k, 9 * c, mm[:, 9:12] @ pij))
                blocks1.append((9 * k, 9 * c + 3, mm[:, 12:15] @ pij))
    return _assemble(blocks0, 9 * nf), _assemble(blocks1, 9 * nf)


def _assemble(blocks: list[tuple[int, int, np.ndarray]], n: int) -> sparse.csr_matrix:
    """An n×n sparse matrix of dense blocks (row, column, block); none overlap."""
    rows, cols, vals = [], [], []
    for r, c, b in blocks:
        rr, cc = np.indices(b.shape)
        rows.append((rr + r).ravel())
        cols.append((cc + c).ravel())
        vals.append(b.ravel())
    if not blocks:
        return sparse.csr_matrix((n, n))
    return sparse.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)
    )


def _rho(t0: sparse.csr_matrix, t1: sparse.csr_matrix, stale: bool) -> float:
    """Spectral radius of the post-update loop T0 + T1, or (``stale``) of the one-step
    stale loop [[T0, T1], [I, 0]]."""
    n = t0.shape[0]
    if stale:
        loop = sparse.bmat([[t0, t1], [sparse.identity(n), None]], format="csr")
    else:
        loop = (t0 + t1).tocsr()
    return spectral_radius(loop)


def spectral_radius(m: sparse.csr_matrix) -> float:
    """max |λ| of the square matrix ``m``: every eigenvalue (numpy, dense) up to order
    :data:`DENSE_MAX`; above it the :data:`ARPACK_K` of largest modulus (ARPACK, from a
    fixed start vector: the same answer every run), dense again if ARPACK does not
    converge within :data:`ARPACK_MAXITER` restarts and the order is at most
    :data:`DENSE_FALLBACK_MAX`, else NaN (not computed; logged). Dense eigenvalues cost
    O(n³): 6.4 s for the four loops of a 125-agent grid (orders 1089 and 2178), against
    about 0.1 s sparse; on grid64 the two agree to 10 digits (docs/performance.md)."""
    n = m.shape[0]
    if n <= DENSE_MAX:
        return float(np.max(np.abs(np.linalg.eigvals(m.toarray()))))
    v0 = np.random.default_rng(0).standard_normal(n)
    try:
        ev = eigs(m, k=ARPACK_K, which="LM", v0=v0, ncv=min(n - 1, ARPACK_NCV), tol=0.0,
                  maxiter=min(20 * n, ARPACK_MAXITER), return_eigenvectors=False)
    except ArpackNoConvergence:
        if n > DENSE_FALLBACK_MAX:
            log.warning("spectral radius of a loop of order %d: ARPACK did not converge "
                        "and a dense solve is past order %d: not computed", n,
                        DENSE_FALLBACK_MAX)
            return math.nan
        log.debug("spectral radius of order %d: ARPACK did not converge, dense", n)
        return float(np.max(np.abs(np.linalg.eigvals(m.toarray()))))
    return float(np.max(np.abs(ev)))


def gain_report(
    form: Formation, beta: tuple[float, ...], dt: float, substeps: int,
    leader_anchor: float = 0.0, kappa: tuple[float, ...] = (0.0, 0.0),
) -> GainReport:
    """Per-channel and sampled-loop stability numbers of the DESO gains (Departure 7).

    The channels are the eigenvalues of the observer's Laplacian
    ``L_ff + leader_anchor·blockdiag(m_i I₃)`` (m_i leaders sensed by follower i;
    ``Formation.observer_laplacian``; = L_ff for the paper's observer), or for a large
    formation the samples of :func:`channels` across the ends of its spectrum. When a
    channel is not Hurwitz the sampled loops are not computed (their radii NaN): the
    report fails on the channel alone.
    """
    b1, b2, b3 = (float(x) for x in beta)
    lam = channels(form.observer_eigs(leader_anchor), 3 * len(form.follower_idx))
    margin = b1 * b2 * lam - b3
    k2, k3 = (float(k) for k in kappa)
    poles = [
        np.linalg.eigvals(np.array([[-b1 * x, 1.0, 0.0], [-b2 * x, -k2 * x, 1.0],
                                    [-b3 * x, -k3 * x, 0.0]]))
        for x in lam
    ]
    max_re = float(max(np.max(p.real) for p in poles))
    # a channel not Hurwitz fails the report whatever the loops give, and their spectral
    # radii take minutes past a thousand agents: then they are not computed (NaN)
    rho_post = rho_stale = rho_e = rho_s = math.nan
    if max_re < 0.0:
        rho_post, rho_stale, rho_e, rho_s = _loop_radii(form, (b1, b2, b3), dt, substeps,
                                                        leader_anchor, (k2, k3))
    return GainReport(
        beta=(b1, b2, b3),
        dt=dt,
        substeps=substeps,
        lambda_ff=lam,
        margin=margin,
        max_real_pole=max_re,
        fastest_bandwidth=b1 * float(lam[-1]),
        euler_number=dt / substeps * b1 * float(lam[-1]),
        rho_post_update=rho_post,
        rho_stale=rho_stale,
        rho_euler_post=rho_e,
        rho_single_euler_stale=rho_s,
        paper_condition=bool(b2 > b1 + b3 / float(lam[0])),
        kappa=(k2, k3),
    )


def _loop_radii(
    form: Formation, beta: tuple[float, float, float], dt: float, substeps: int,
    leader_anchor: float, kappa: tuple[float, float],
) -> tuple[float, float, float, float]:
    """The spectral radii of :class:`GainReport`'s four sampled loops: exact sub-steps
    post-update and one-step stale, Euler sub-steps post-update, one Euler step stale."""
    la = leader_anchor
    t0, t1 = _network_transition(form, beta, dt, substeps, euler=False, leader_anchor=la,
                                 kappa=kappa)
    e0, e1 = _network_transition(form, beta, dt, substeps, euler=True, leader_anchor=la,
                                 kappa=kappa)
    s0, s1 = _network_transition(form, beta, dt, 1, euler=True, leader_anchor=la,
                                 kappa=kappa)
    return (_rho(t0, t1, stale=False), _rho(t0, t1, stale=True), _rho(e0, e1, stale=False),
            _rho(s0, s1, stale=True))


def channels(lam: np.ndarray, order: int) -> np.ndarray:
    """The channels a gain report checks: ``lam`` itself when it holds all ``order``
    eigenvalues; when it holds only the two ends of a large formation's spectrum
    (:func:`swarm_common.scenario.spectra.spectrum`), :data:`CHANNEL_SAMPLES` values
    spaced geometrically from λ_min to λ_max. Every eigenvalue lies in that interval; the
    margin β1β2λ − β3 is least at λ_min, which is exact, and the slowest pole is taken
    over the samples (docs/performance.md, "Start-up of a large formation")."""
    if len(lam) == order or len(lam) < 2 or not lam[0] > 0.0:
        return lam
    return np.geomspace(float(lam[0]), float(lam[-1]), CHANNEL_SAMPLES)


# the gain report of a formation's content and observer gains, once per process
_reports: ContentMemo[GainReport] = ContentMemo()


def formation_gain_report(form: Formation, obs: ObserverConfig, dt: float) -> GainReport:
    """:func:`gain_report` of a scenario's observer gains, once per formation content and
    gains in a process: every follower of a formation has the same report, and so does
    every run of a sweep over one scenario (its dense eigenvalue problems take 0.66 s at
    64 agents; :meth:`Formation.content_digest`)."""
    params = (tuple(obs.beta), dt, obs.substeps, obs.leader_anchor, tuple(obs.velocity_gain))
    return _reports.get((form.content_digest(), params), lambda: gain_report(form, *params))


def scenario_gain_problem(sc: Scenario) -> str | None:
    """:meth:`GainReport.problem` of ``sc``'s followers' observers (memoised: a daemon of
    the same process pays nothing more), or None when it passes."""
    report = formation_gain_report(formation_from_scenario(sc), sc.observer, sc.control_dt)
    return report.problem()
