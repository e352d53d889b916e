"""Parameters of the neighbour tracker (paper Section IV), validated on construction.

Every choice the paper leaves open is a field here, with the reason for its default:

=================================  ==========  ============================================
field                              default     reason
=================================  ==========  ============================================
``n_particles_total``              2000        P_T, fixed budget per robot (authors: 10 000;
                                               2000 is calibrated up to N = 12 in the tests
                                               and costs ~0.3 ms (single models) to ~0.4 ms
                                               (mixture) per robot-step in a bank)
``min_particles_per_neighbour``    20          floor of each P_j so a far neighbour keeps a
                                               usable cloud; lowered to ``P_T // M`` when
                                               ``M * floor > P_T``
``allocation_scale_m``             2.0         importance w_j = 1 / (d_ij + s), s = D_s:
                                               inside / touching ellipses weigh 1/s
``motion_model``                   ``auto``    ``auto`` = ``mixture`` in both scenarios:
                                               one model calibrated whatever the neighbours
                                               do (see below); Eq. 20 alone had the truth
                                               in the 95% ellipse in 41-51% of steps under
                                               random actions. The paper's single models
                                               stay selectable: ``coverage`` (Eq. 20),
                                               ``crossing`` (Eq. 22), ``static``
``k_p``                            0.5         Eq. 20 gain (1/s), the authors' motion model
``coverage_standoff_m``            ``None``    Eq. 20's pull stops this far from q_m; None:
                                               R_s + D_s (8 m): coverage robots park around
                                               the peak, not on it; 0 is the paper's law,
                                               overconfident for long-unseen robots parked
                                               off the peak (see the calibration tests)
``process_noise_m_per_sqrt_s``     1.5         position random walk: per-step std
                                               ``q sqrt(dt)`` per axis (0.67 m at dt 0.2 s;
                                               the authors used 0.5 m per 0.25 s step, i.e.
                                               1.0; 1.5 keeps long-unseen neighbours inside
                                               their 95% ellipse, see the tests)
``heading_noise_rad_per_sqrt_s``   0.7         relative-heading random walk (0.31 rad/step)
``init_mode``                      ``auto``    known starts when given (Eq. 1, the paper's
                                               assumption), else uniform over the arena
``init_spread_m``                  0.1         std of the cloud around a known start
``init_heading_spread_rad``        0.1         same for the heading
``confidence``                     0.95        ellipse level (chi^2, 2 dof)
``mc_error_factor``                15.0        kappa: the reported covariance is the
                                               particle covariance times (1 + kappa/ESS),
                                               adding the Monte Carlo error of the particle
                                               mean (measured against an exact Kalman
                                               filter: ~10-17 Sigma/ESS when resampling
                                               every step); 0 reports the bare covariance
``recovery_min_ess``               10.0        detected neighbour whose weighted set has an
                                               effective size below ``min(this, P_j / 2)``
                                               is re-seeded around the detection
``ess_recovery``                   ``reseed``  ... from N(z, Sigma_MEAS); ``fuse``: its own
                                               cloud mapped onto the Gaussian posterior
                                               of its moments and z (tracker step 4)
``recovery_gate_chi2``             27.63       ... as is one whose nearest particle is
                                               farther than this squared Mahalanobis
                                               distance (chi^2 2 dof, p = 1e-6)
``recovery_bias_alpha``            0.0         ... and one whose detections have missed
``recovery_bias_chi2``             13.82       the cloud's mean on one side: the EWMA
                                               (weight alpha, over detected steps) of
                                               the residual ``Σ_MEAS^{-1/2} (z − mean)``
                                               beyond this chi^2 (2 dof, p = 1e-3) times
                                               its variance ``alpha / (2 − alpha)``;
                                               alpha 0 (the default) turns the test off;
                                               the safety filter uses 0.2 (its
                                               ``FILTER_TRACKER_DEFAULTS`` say why; see
                                               the tracker's step 4)
``recovery_reseed``                ``local``   a neighbour whose particles the view
                                               deleted (Eq. 4) is re-seeded outside F_i
                                               in a disc around the deleted cloud
                                               (``arena``: over the whole arena)
``recovery_local_margin_m``        2.5         margin of that disc beyond the deleted
                                               cloud's extent (m)
``ego_motion``                     ``action``  own motion from the applied action (Eq. 2);
                                               ``pose``: from the own pose in consecutive
                                               observations
``clamp_to_arena``                 True        particles are clamped to the arena like robots
``min_meas_var``                   1e-4        floor of Sigma_MEAS entries (noiseless
                                               cameras still give a finite likelihood)
``mode_prior_static``              0.32        mixture: weights of the modes (normalised by
``mode_prior_coverage``            0.06        their sum) in a fresh cloud (Eq. 1, re-seeds)
``mode_prior_crossing``            0.08        and for a switching particle's new mode;
``mode_prior_cv``                  0.54        measured (table below): most neighbours that
                                               move hold a velocity for seconds, so cv is
                                               the largest; Eq. 20/22 are small hedges
``mode_switch_rate_hz``            0.12        Markov switching per particle: per-step
                                               probability ``1 − e^{−rate dt}`` (0.0237 at
                                               dt 0.2 s): the mode posterior learnt from
                                               detections is forgotten in ~1/rate = 8 s
                                               unseen (measured at 0.02/s: smooth random
                                               motion 0.87; at 0.1/s with a looser cv
                                               mode: straight drivers 0.64)
``mixture_noise_m_per_sqrt_s``     1.25        position random walk of the static, Eq. 20
                                               and Eq. 22 modes (0.56 m/step): the static
                                               mode is the mixture's "anything" mode
``cv_noise_m_per_sqrt_s``          0.15        position noise of the cv mode (0.067 m/step)
``cv_velocity_noise_mps_per_sqrt_s`` 0.08      cv velocity random walk (0.036 m/s per step,
                                               driven by the same normals as the position
                                               noise): nearly rigid, a robot going straight
                                               keeps its line for tens of seconds unseen;
                                               turns are covered by the static mode and
                                               switches (0.3: straight drivers are lost)
``cv_forward_bias``                1.5         a fresh cv velocity (start, re-seed, switch)
                                               is ``v_max (b + n_x, n_y)`` in the particle's
                                               heading frame, shrunk to v_max: mostly ahead
                                               at full speed (robots drive where they look;
                                               from a known start this tracks a neighbour
                                               that drives off unseen)
=================================  ==========  ============================================

The mode mixture (``motion_model="mixture"``, :func:`~fov_marl.estimation.kernels.mixture_predict`)
---------------------------------------------------------------------------------------------------
Each particle carries a mode (static random walk; Eq. 20 towards q_m with the standoff;
Eq. 22 towards robot i at v_max/2; constant velocity with its own velocity state) that
switches at ``mode_switch_rate_hz``; detections re-weight the particles, so the mode
probabilities (``TrackerEstimate.mode_probs``) are updated by Bayes through the weights
and the resampling, with no explicit mode filter. The parameters were tuned from
measurements (a random search over ~80 sets on 2-3 seeds, then local refinement and a
check on 7 seeds), not guessed. Result, truth inside the 95% ellipse pooled over every
(robot, neighbour) pair and step, N = 6, β = 120°, 40 m arena, 10 seeds (10-19, not
used for tuning) x 300 steps (``python -m tests.estimation.calibration_table --models
mixture static coverage --seeds 10 ... 19``):

===============  ========================  =========  =========  =================
behaviour        mixture: rate, mean a     static     coverage   what it does
                 (all / pairs within 10 m)  (q = 1.5)  (Eq. 20)
===============  ========================  =========  =========  =================
pfcbf            0.963, 2.9 / 2.0 m        0.947      0.992      the paper's
                                                                 controller
random           0.975, 9.8 / 8.8 m        0.996      0.996      uniform actions
smooth random    0.954, 10.3 / 4.1 m       0.996      0.922      OU velocity
straight         0.918, 19.0 / 12.8 m      0.467      0.197      [1, 0, 0] always
charge centre    0.969, 6.1 / 6.1 m        0.995      0.995      full speed at the
                                                                 team centroid
spin + charge    0.942, 2.3 / 2.3 m        0.840      0.835      ... spinning
chase            0.965, 4.0 / 4.0 m        0.995      0.995      cyclic pursuit
wait + charge    0.968, 3.8 / 3.7 m        0.995      0.994      still U[5, 40] s
===============  ========================  =========  =========  =================

Mean semi-major axis of the detected neighbours 0.5-0.7 m, of those unseen for < 5 s
1.4-3.5 m. At N = 12 the mixture's rates are 0.922-0.956. pfcbf runs in
``fov_coverage_v0`` from the paper's random starts; the others in the MiniWorld from a
clustered start (a team deployed together, ``testing.clustered_poses``): from random
starts in the 40 m arena most pairs never come within
camera range in 60 s, and the rate measures the prior of never-seen robots (mixture
0.85-0.996 there; e.g. uniform random actions 0.994 overall but 0.962 for the pairs
within 10 m). Long-unseen neighbours of every behaviour get large ellipses (the prior
regains weight in ~1/rate = 8 s): the price of covering robots that may start charging
while unseen. Longer episodes drift up for the same reason (6 x 600 steps: 0.919-0.978).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from fov_marl.validation import ConfigError, check_bool, check_choice, check_int, check_real

__all__ = ["TrackerParams", "MotionModel", "InitMode", "EgoMotion", "MAX_NOISE"]

MotionModel = Literal["auto", "mixture", "coverage", "crossing", "static"]
InitMode = Literal["auto", "known", "uniform"]
EgoMotion = Literal["action", "pose"]
RecoveryReseed = Literal["local", "arena"]
EssRecovery = Literal["reseed", "fuse"]

_MOTION_MODELS = ("auto", "mixture", "coverage", "crossing", "static")
_INIT_MODES = ("auto", "known", "uniform")
_EGO_MOTIONS = ("action", "pose")
_RECOVERY_RESEEDS = ("local", "arena")
_ESS_RECOVERIES = ("reseed", "fuse")

#: Upper bound of the noise intensities and spreads (m/sqrt(s), rad/sqrt(s), m, rad) and
#: of the other unbounded reals: particle clouds stay finite in float64 far below it.
MAX_NOISE = 1e6

#: Real fields: name -> (lo, hi, lo_open, hi_open).
_REAL_FIELDS: dict[str, tuple[float, float, bool, bool]] = {
    "allocation_scale_m": (0.0, MAX_NOISE, True, False),
    "k_p": (0.0, MAX_NOISE, False, False),
    "process_noise_m_per_sqrt_s": (0.0, MAX_NOISE, False, False),
    "heading_noise_rad_per_sqrt_s": (0.0, MAX_NOISE, False, False),
    "init_spread_m": (0.0, MAX_NOISE, False, False),
    "init_heading_spread_rad": (0.0, MAX_NOISE, False, False),
    "confidence": (0.0, 1.0, True, True),
    "mc_error_factor": (0.0, MAX_NOISE, False, False),
    "recovery_min_ess": (0.0, 1e9, False, False),
    "recovery_gate_chi2": (0.0, 1e9, True, False),
    "recovery_bias_alpha": (0.0, 1.0, False, False),
    "recovery_bias_chi2": (0.0, 1e9, True, False),
    "recovery_local_margin_m": (0.0, MAX_NOISE, False, False),
    "min_meas_var": (0.0, MAX_NOISE, True, False),
    # mode mixture (motion_model="mixture")
    "mode_prior_static": (0.0, 1.0, False, False),
    "mode_prior_coverage": (0.0, 1.0, False, False),
    "mode_prior_crossing": (0.0, 1.0, False, False),
    "mode_prior_cv": (0.0, 1.0, False, False),
    "mode_switch_rate_hz": (0.0, MAX_NOISE, False, False),
    "mixture_noise_m_per_sqrt_s": (0.0, MAX_NOISE, False, False),
    "cv_noise_m_per_sqrt_s": (0.0, MAX_NOISE, False, False),
    "cv_velocity_noise_mps_per_sqrt_s": (0.0, MAX_NOISE, False, False),
    "cv_forward_bias": (0.0, MAX_NOISE, False, False),
}


@dataclass(frozen=True)
class TrackerParams:
    """Parameters of one robot's particle-filter bank; see the module docstring.

    Every field is type-checked and range-checked on construction through
    :mod:`fov_marl.validation` (reals must be real numbers, not bools, strings or
    complex; integers must be integers; NumPy scalars are accepted and stored as Python
    numbers); the first bad field raises :class:`~fov_marl.validation.ConfigError` (a
    ``ValueError``) naming the field, the value and the allowed range.

    Attributes:
        n_particles_total: P_T, particles shared by all neighbours, an integer in
            [1, 10_000_000] (resource guard: 10^7 particles of 3 float64 are 240 MB per
            robot); must be at least the number of neighbours (checked by the tracker,
            which knows N).
        min_particles_per_neighbour: floor of each P_j, an integer in [1, 10_000_000].
        allocation_scale_m: s in the importance weight ``1 / (d_ij + s)``, in (0, 1e6] m.
        motion_model: neighbour input u_j^est for the prediction (Eq. 2): ``"mixture"``
            (the mode mixture of the module docstring), ``"coverage"`` (Eq. 20),
            ``"crossing"`` (Eq. 22), ``"static"`` (zero input, noise only) or ``"auto"``
            (``"mixture"`` in both scenarios).
        k_p: gain K_p of Eq. 20, in [0, 1e6] 1/s.
        coverage_standoff_m: ρ of :func:`~fov_marl.estimation.kernels.coverage_input`,
            in [0, 1e6] m, or None for ``sensing_radius_m + safety_distance_m``.
        process_noise_m_per_sqrt_s: position random-walk intensity q, in [0, 1e6]; each
            step adds N(0, q^2 dt) per axis.
        heading_noise_rad_per_sqrt_s: heading random-walk intensity, in [0, 1e6].
        init_mode: ``"known"`` (requires initial poses at reset), ``"uniform"``, or
            ``"auto"`` (known when initial poses are given, else uniform).
        init_spread_m: std of the known-start cloud per axis, in [0, 1e6] m.
        init_heading_spread_rad: std of the known-start heading, in [0, 1e6] rad.
        confidence: ellipse confidence level, in (0, 1).
        mc_error_factor: κ of the Monte Carlo inflation of the reported covariance,
            in [0, 1e6].
        recovery_min_ess: effective-sample-size threshold of the re-seed around a
            detection, in [0, 1e9].
        ess_recovery: what a detected neighbour whose weighted set fell below that
            effective size (and passed the χ² gate and the bias test) becomes:
            ``"reseed"`` (the default) a fresh cloud from N(z, Σ_MEAS); ``"fuse"`` its
            own cloud moved and shrunk onto the Gaussian posterior of its moments and
            the detection (tracker step 4; the safety filter's default, its
            ``FILTER_TRACKER_DEFAULTS`` say why).
        recovery_gate_chi2: squared-Mahalanobis gate of the re-seed, in (0, 1e9].
        recovery_bias_alpha: weight of the newest residual in the bias test's moving
            average (tracker step 4), in [0, 1]; 0 (the default) turns the test off
            (the safety filter's default is 0.2).
        recovery_bias_chi2: threshold of the bias test, a χ² (2 dof) quantile, in
            (0, 1e9].
        recovery_reseed: where a neighbour whose particles were all deleted by the view
            (Eq. 4) is re-seeded, outside F_i: ``"local"`` (the default) uniform in the
            disc around the deleted cloud's mean of radius (the cloud's largest particle
            distance from its mean) + ``recovery_local_margin_m``, the neighbour having
            just been where the belief was but not where the view now looks; or
            ``"arena"``, uniform over the whole arena (the first versions' choice; a
            belief lost next to the view then spreads over tens of metres and the
            safety rows lose a neighbour that is 2 m away).
        recovery_local_margin_m: margin of the ``"local"`` re-seed disc, in [0, 1e6] m:
            how far the truth may lie outside the failed cloud.
        ego_motion: ``"action"`` or ``"pose"`` (how Σ_i's own motion is obtained).
        clamp_to_arena: clamp particle positions to ``[r, L - r]^2`` like the env does
            (a bool).
        min_meas_var: floor of each Σ_MEAS diagonal entry, in (0, 1e6].
        mode_prior_static, mode_prior_coverage, mode_prior_crossing, mode_prior_cv:
            mixture mode weights, each in [0, 1], not all 0 (normalised by their sum,
            :meth:`mode_prior`).
        mode_switch_rate_hz: mixture switching rate per particle, in [0, 1e6] 1/s; the
            per-step probability is ``1 − exp(−rate dt)``.
        mixture_noise_m_per_sqrt_s: position random walk of the mixture's static, Eq. 20
            and Eq. 22 modes, in [0, 1e6].
        cv_noise_m_per_sqrt_s: position noise of the constant-velocity mode, in [0, 1e6].
        cv_velocity_noise_mps_per_sqrt_s: its velocity random walk, in [0, 1e6] m/s/√s.
        cv_forward_bias: forward bias b of a fresh constant-velocity draw, in [0, 1e6]
            (0: isotropic).
    """

    n_particles_total: int = 2000
    min_particles_per_neighbour: int = 20
    allocation_scale_m: float = 2.0
    motion_model: MotionModel = "auto"
    k_p: float = 0.5
    coverage_standoff_m: float | None = None
    process_noise_m_per_sqrt_s: float = 1.5
    heading_noise_rad_per_sqrt_s: float = 0.7
    init_mode: InitMode = "auto"
    init_spread_m: float = 0.1
    init_heading_spread_rad: float = 0.1
    confidence: float = 0.95
    mc_error_factor: float = 15.0
    recovery_min_ess: float = 10.0
    ess_recovery: EssRecovery = "reseed"
    recovery_gate_chi2: float = -2.0 * math.log(1e-6)
    recovery_bias_alpha: float = 0.0
    recovery_bias_chi2: float = -2.0 * math.log(1e-3)
    recovery_reseed: RecoveryReseed = "local"
    recovery_local_margin_m: float = 2.5
    ego_motion: EgoMotion = "action"
    clamp_to_arena: bool = True
    min_meas_var: float = 1e-4
    mode_prior_static: float = 0.32
    mode_prior_coverage: float = 0.06
    mode_prior_crossing: float = 0.08
    mode_prior_cv: float = 0.54
    mode_switch_rate_hz: float = 0.12
    mixture_noise_m_per_sqrt_s: float = 1.25
    cv_noise_m_per_sqrt_s: float = 0.15
    cv_velocity_noise_mps_per_sqrt_s: float = 0.08
    cv_forward_bias: float = 1.5

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(
            self,
            "n_particles_total",
            check_int("n_particles_total", self.n_particles_total, 1, 10_000_000),
        )
        set_(
            self,
            "min_particles_per_neighbour",
            check_int(
                "min_particles_per_neighbour", self.min_particles_per_neighbour, 1, 10_000_000
            ),
        )
        set_(self, "motion_model", check_choice("motion_model", self.motion_model, _MOTION_MODELS))
        set_(self, "init_mode", check_choice("init_mode", self.init_mode, _INIT_MODES))
        set_(self, "ego_motion", check_choice("ego_motion", self.ego_motion, _EGO_MOTIONS))
        set_(self, "clamp_to_arena", check_bool("clamp_to_arena", self.clamp_to_arena))
        set_(
            self,
            "recovery_reseed",
            check_choice("recovery_reseed", self.recovery_reseed, _RECOVERY_RESEEDS),
        )
        set_(
            self,
            "ess_recovery",
            check_choice("ess_recovery", self.ess_recovery, _ESS_RECOVERIES),
        )
        if self.coverage_standoff_m is not None:
            set_(
                self,
                "coverage_standoff_m",
                check_real(
                    "coverage_standoff_m", self.coverage_standoff_m, 0.0, MAX_NOISE,
                    note="(or None)",
                ),
            )  # fmt: skip
        for name, (lo, hi, lo_open, hi_open) in _REAL_FIELDS.items():
            value = check_real(name, getattr(self, name), lo, hi, lo_open=lo_open, hi_open=hi_open)
            set_(self, name, value)
        priors = self._mode_weights()
        if sum(priors) <= 0.0:
            raise ConfigError(
                "mode_prior_static + mode_prior_coverage + mode_prior_crossing + mode_prior_cv "
                f"must be > 0, got {sum(priors)!r}"
            )

    def _mode_weights(self) -> tuple[float, float, float, float]:
        return (
            self.mode_prior_static,
            self.mode_prior_coverage,
            self.mode_prior_crossing,
            self.mode_prior_cv,
        )

    def mode_prior(self) -> tuple[float, float, float, float]:
        """The mixture's mode prior ``(static, coverage, crossing, cv)``, normalised to sum 1
        (the ``mode_prior_*`` fields are weights)."""
        w = self._mode_weights()
        total = sum(w)
        return tuple(x / total for x in w)  # type: ignore[return-value]
