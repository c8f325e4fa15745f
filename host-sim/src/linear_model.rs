//! The paper-mode closed loop as a linear model of its own: a second method beside the
//! time-domain simulation of `sim.rs`, sharing only the plant's equations (eqs. 1-8,
//! [`PlantParams`]) and the gains, not a line of the control code.
//!
//! # What is modelled
//!
//! Everything `sim::run` does with exact sensors and no limit reached, written as linear
//! difference equations (no quantisation, no saturation, no current guard, no f32 rounding):
//!
//! | part                  | rate    | law (k: its own tick)                                                        |
//! |-----------------------|---------|------------------------------------------------------------------------------|
//! | plant, eqs. 1-8       | 20 kHz  | `x[k+1] = Ad x[k] + Bd v[k]`, exact zero-order hold over 50 us (as `plant.rs`) |
//! | current PI            | 20 kHz  | `Ic += Ki_c Tc ec; v = Kp_c ec + Ic`, `ec = i* - i_a` sampled before the step  |
//! | position PID + ff     | 2 kHz   | `Ip += Ki Tp e; i* = Kp e + Ip + Kd (e - e_prev)/Tp + Kv s + Ka a`, `e = sp - theta_rot` |
//! | interpolator          | 100 Hz  | `s = (r[n] - r[n-1])/T`, `a = (s - s_prev)/T`, `sp = r[n-1] + (r[n] - r[n-1]) m/20` |
//!
//! with the call order of `paper_mode.rs` and `sim.rs`: at `t = nT` the sample `r[n]` is pushed,
//! then 20 position ticks `m = 0..19`, each sampling the motor angle at `nT + m Tp`, computing
//! `i*` and holding it over the 10 current ticks that follow; each current tick samples the
//! current, computes the voltage and holds it for `Tc` = 50 us. (The integrators include this
//! tick's error, as the firmware's conditional integration does when nothing saturates.)
//!
//! # Why lifting, and why it is exact
//!
//! The loop runs at three rates, so it is not time-invariant at any one of them; it is
//! *periodic* with the reference period `T` = 10 ms. Two exact reductions make it LTI:
//!
//! 1. **2 kHz lift.** Within one position tick `i*` is held, so the ten current ticks compose to
//!    one linear map of the state `[x, Ic]` and `i*`: `(Ai, bi) = (Ac^10, sum Ac^j bc)`. With the
//!    PID this gives the 2 kHz closed loop `q[k+1] = Acl q[k] + Bcl [sp, ff]`,
//!    `q = [x (7), Ic, Ip, e_prev]`, an ordinary LTI system. Its eigenvalues are the closed-loop
//!    poles (the interpolator is outside the loop: it only shapes the reference), mapped to the
//!    continuous equivalents `s = ln(lambda) / Tp`, unambiguous below the 1 kHz Nyquist limit of
//!    the position loop; and breaking it at `i*` gives the loop transfer
//!    `L(z) = C(z) P(z)`, `P = theta_rot / i*`, `C = Kp + Ki Tp/(1 - 1/z) + Kd (1 - 1/z)/Tp`,
//!    whose margins [`LinearModel::margins`] reports.
//! 2. **10 ms lift.** Over one reference period the 20 position ticks, with the set-point a
//!    linear function of `r[n-1]`, `r[n]` and the previous slope, compose to
//!    `S[n+1] = Phi S[n] + Gamma r[n]`, `S = [q (10), r[n-1], s[n-1]]` (the interpolator's memory).
//!    For `r[n] = e^{j w n T}` the steady state is `S = (zI - Phi)^-1 Gamma`, `z = e^{j w T}`,
//!    and the output after position tick `m` of every period is
//!    `y[n, m] = g_m(w) e^{j w n T}` with `g_m` linear in `[S; 1]`. Nothing is approximated:
//!    this is the exact periodic steady state of the linear loop (the standard lifting of a
//!    periodic discrete system, as in Chen & Francis, *Optimal Sampled-Data Control Systems*,
//!    1995), computed from exact products of the per-tick matrices.
//!
//! # What a frequency response means here
//!
//! A periodic system answers a sinusoid with the sinusoid plus images at `f +- k 100 Hz`, so
//! "the" response must say where the output is looked at. [`LinearModel::response`] gives what
//! host-sim's log and the H1 estimator of `analysis.rs` see: a row at the end of every
//! `2000 / log_rate` position ticks, stamped at that instant, holding the reference sample of
//! its period (the 100 Hz staircase) and the angle after the interval's last current tick. For `r[n] = e^{j w n T}`
//! the rows are `x_j = e^{j w n T}` and `y_j = g_m e^{j w n T}`, so the ratio of their DTFTs at
//! `w` (which is what `Sxy / Sxx` converges to; the images lie at 90 Hz and above, outside the
//! 0-10 Hz band) is
//!
//! ```text
//!            sum_m g_m(w) e^{-j w m Tp}
//!   H(w) = ------------------------------   over the logged ticks m of a period
//!               sum_m e^{-j w m Tp}
//! ```
//!
//! This includes the staircase's half-period shift (the logged reference is the held sample),
//! so the analytic curve and the measured one are the same quantity and can be compared to
//! a fraction of a degree. `tests/analytic_vs_sim.rs` does that.
//!
//! # How it is checked
//!
//! `tests/analytic_vs_sim.rs`: on a steady 0.5 deg multisine (0.2-10 Hz) the simulation's H1
//! estimate and this model agree to 5e-7 dB and 2e-6 deg, for the column and the motor (the rest is
//! the firmware's f32 arithmetic). A loop built there from the firmware's own parts with a
//! defective acceleration feedforward (`slope / T`, every on-time sample taken for a late one)
//! matches this model with [`AccelFeedforward::SlopeOverPeriod`] as closely, and misses the fixed
//! model by 5.8 dB and 21 deg: the comparison would have caught the defect.
//!
//! # The physical limit
//!
//! [`PhysicalLimit`] answers a different question from the same plant: whatever the controller,
//! what current and voltage amplitude does the motor need to hold a sinusoidal pinion angle
//! (`delta_P`, the column encoder's angle) of a given amplitude at `f` in steady state? From
//! the continuous plant, `i/v` and `delta_P/v` at `j w` give both per unit pinion amplitude; the
//! largest amplitude within the current and voltage limits follows, and from it the highest
//! frequency at which a sweep of amplitude `A` can still reach `10^(-3/20) A`: an upper bound on
//! any controller's -3 dB bandwidth on this plant.

use crate::plant::{PlantParams, state};
use nalgebra::{Complex, DMatrix, DVector, RowDVector, SMatrix, SVector};
use std::f64::consts::TAU;
use steering_ecu::ecu_mode::EcuTuning;
use steering_ecu::gains::{EposGains, GainError};
use steering_ecu::paper_mode::{
    CURRENT_LOOP_HZ, CURRENT_TICKS_PER_POSITION_TICK, POSITION_LOOP_HZ,
    POSITION_TICKS_PER_REFERENCE, REFERENCE_HZ,
};

/// Number of states of the 2 kHz closed loop: plant (7), current integrator, position
/// integrator, previous position error.
const NQ: usize = 10;
/// Index of the current integrator, the position integrator and the previous error in `q`.
const IC: usize = 7;
const IP: usize = 8;
const EPREV: usize = 9;
/// States of the 10 ms lift: `q`, the last sample (motor rad) and the last slope (motor rad/s).
const NS: usize = NQ + 2;
const RLAST: usize = NQ;
const SLAST: usize = NQ + 1;
/// Columns of the per-period maps: `[S; r]`.
const NW: usize = NS + 1;

/// How the interpolator's acceleration feedforward is formed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AccelFeedforward {
    /// The change of slope per period, `(s[n] - s[n-1]) / T`: `reference.rs` since the fix.
    #[default]
    ChangeOfSlope,
    /// `s[n] / T`, a defect the interpolator once had (every on-time sample taken as late). Kept
    /// so that a test can show the model tells the two apart.
    SlopeOverPeriod,
}

/// Which angle a response is of; both per unit reference at the wheel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    /// The column encoder's angle, delta_P at the pinion end (sec. 3.2), as the log's `sw_deg`.
    Column,
    /// The motor angle divided by the rigid gear ratio (85.5), as `motor_rad` / ratio.
    Motor,
}

/// The gains the model runs on, SI, f64 (converted from the same f32 values the firmware uses).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ModelGains {
    pub current_kp: f64,
    pub current_ki: f64,
    pub position_kp: f64,
    pub position_ki: f64,
    pub position_kd: f64,
    pub ff_velocity: f64,
    pub ff_acceleration: f64,
}

impl ModelGains {
    pub fn from_epos(gains: &EposGains) -> Result<Self, GainError> {
        let si = gains.to_si()?;
        Ok(ModelGains {
            current_kp: si.current_kp() as f64,
            current_ki: si.current_ki() as f64,
            position_kp: si.position_kp() as f64,
            position_ki: si.position_ki() as f64,
            position_kd: si.position_kd() as f64,
            ff_velocity: si.ff_velocity() as f64,
            ff_acceleration: si.ff_acceleration() as f64,
        })
    }
}

/// A closed-loop pole as its continuous equivalent.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Pole {
    /// rad/s
    pub re: f64,
    /// rad/s
    pub im: f64,
    /// |s|, rad/s
    pub wn: f64,
    /// |s| / 2 pi, Hz
    pub f_hz: f64,
    /// -re / |s| (1 for a real stable pole)
    pub zeta: f64,
    /// |lambda| of the 2 kHz lift (< 1: stable)
    pub z_magnitude: f64,
}

/// Where the loop transfer's phase crosses -180 deg (mod 360): the gain margin there.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct GainCrossing {
    pub f_hz: f64,
    /// `-20 log10 |L|`: positive = the gain may rise by this much, negative = fall by this much.
    pub margin_db: f64,
}

/// Where |L| crosses 1: the phase margin there.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PhaseCrossing {
    pub f_hz: f64,
    /// `180 + arg L`, wrapped to (-180, 180] deg.
    pub margin_deg: f64,
}

/// Stability margins of the position loop, broken at the current set-point `i*`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Margins {
    /// The smallest gain-increase margin (over phase crossovers with |L| < 1), dB.
    pub gain_margin_db: Option<f64>,
    pub phase_crossover_hz: Option<f64>,
    /// The smallest phase margin over all gain crossovers, deg.
    pub phase_margin_deg: Option<f64>,
    pub gain_crossover_hz: Option<f64>,
    /// Every -180 deg crossing and every |L| = 1 crossing found between 0.01 Hz and 1 kHz.
    pub phase_crossovers: Vec<GainCrossing>,
    pub gain_crossovers: Vec<PhaseCrossing>,
}

/// The linearised paper-mode closed loop.
#[derive(Debug, Clone)]
pub struct LinearModel {
    params: PlantParams,
    gains: ModelGains,
    accel_ff: AccelFeedforward,
    /// Motor rad per steering rad (the cascade's gearing).
    ratio: f64,
    tp: f64,
    /// One position tick of plant + current loop, state `[x, Ic]`, input `i*`.
    a_inner: DMatrix<f64>,
    b_inner: DVector<f64>,
    /// The 2 kHz closed loop, state `q`, inputs `[sp, ff]` (motor rad, A).
    a_cl: DMatrix<f64>,
    b_cl: DMatrix<f64>,
    /// The 10 ms lift.
    phi: DMatrix<f64>,
    gamma: DVector<f64>,
    /// `q` after position tick `m` of a period as a linear map of `[S; r]` (10 x 13 each).
    q_after: Vec<DMatrix<f64>>,
}

/// Why a model could not be built.
#[derive(Debug, Clone, PartialEq)]
pub enum ModelError {
    Gains(GainError),
    /// A parameter that must be finite and positive is not.
    Plant {
        name: &'static str,
        value: f64,
    },
    /// The log rate does not divide the 2 kHz position loop.
    LogRate {
        hz: u32,
    },
}

impl std::fmt::Display for ModelError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ModelError::Gains(e) => write!(f, "gains: {e}"),
            ModelError::Plant { name, value } => {
                write!(f, "plant parameter {name} = {value} is not a valid value")
            }
            ModelError::LogRate { hz } => {
                write!(f, "log rate {hz} Hz does not divide {POSITION_LOOP_HZ} Hz")
            }
        }
    }
}

impl std::error::Error for ModelError {}

/// The plant of eqs. 1-8 discretised exactly (zero-order hold) over `dt`: `(Ad, Bd)`.
fn zoh(params: &PlantParams, dt: f64) -> (SMatrix<f64, 7, 7>, SVector<f64, 7>) {
    let (a, b) = params.electromechanical_state_space();
    let mut aug = SMatrix::<f64, 8, 8>::zeros();
    aug.fixed_view_mut::<7, 7>(0, 0).copy_from(&(a * dt));
    aug.fixed_view_mut::<7, 1>(0, 7).copy_from(&(b * dt));
    let e = aug.exp();
    (
        e.fixed_view::<7, 7>(0, 0).into_owned(),
        e.fixed_view::<7, 1>(0, 7).into_owned(),
    )
}

fn check_plant(params: &PlantParams) -> Result<(), ModelError> {
    for (name, value) in [
        ("ra", params.ra),
        ("la", params.la),
        ("kt", params.kt),
        ("j_rot", params.j_rot),
        ("j_sw", params.j_sw),
        ("belt_reduction", params.belt_reduction),
        ("tau_bs", params.tau_bs),
        ("tau_p", params.tau_p),
        ("j_bs_equivalent", params.j_bs_equivalent()),
    ] {
        if !(value.is_finite() && value > 0.0) {
            return Err(ModelError::Plant { name, value });
        }
    }
    Ok(())
}

impl LinearModel {
    /// The model of `sim::run` with exact sensors for this plant and these gains.
    pub fn new(params: PlantParams, gains: &EposGains) -> Result<Self, ModelError> {
        Self::with_accel_feedforward(params, gains, AccelFeedforward::ChangeOfSlope)
    }

    pub fn with_accel_feedforward(
        params: PlantParams,
        gains: &EposGains,
        accel_ff: AccelFeedforward,
    ) -> Result<Self, ModelError> {
        check_plant(&params)?;
        let g = ModelGains::from_epos(gains).map_err(ModelError::Gains)?;
        let tc = 1.0 / CURRENT_LOOP_HZ as f64;
        let tp = 1.0 / POSITION_LOOP_HZ as f64;
        let t = 1.0 / REFERENCE_HZ as f64;
        let n_c = CURRENT_TICKS_PER_POSITION_TICK as usize;
        let n_p = POSITION_TICKS_PER_REFERENCE as usize;
        let ratio = params.motor_per_pinion();

        // One current tick, state [x (7), Ic], input i*:
        //   ec = i* - i_a;  Ic' = Ic + Ki_c Tc ec;  v = Kp_c ec + Ic';  x' = Ad x + Bd v
        // so v = kc (i* - i_a) + Ic with kc = Kp_c + Ki_c Tc.
        let (ad, bd) = zoh(&params, tc);
        let kc = g.current_kp + g.current_ki * tc;
        let mut ac = DMatrix::<f64>::zeros(8, 8);
        let mut bc = DVector::<f64>::zeros(8);
        for i in 0..7 {
            for j in 0..7 {
                ac[(i, j)] = ad[(i, j)];
            }
            ac[(i, state::CURRENT)] -= kc * bd[i];
            ac[(i, IC)] = bd[i];
            bc[i] = kc * bd[i];
        }
        ac[(IC, state::CURRENT)] = -g.current_ki * tc;
        ac[(IC, IC)] = 1.0;
        bc[IC] = g.current_ki * tc;
        // Ten of them with i* held: one position tick of the inner loop.
        let mut a_inner = DMatrix::<f64>::identity(8, 8);
        let mut b_inner = DVector::<f64>::zeros(8);
        for _ in 0..n_c {
            a_inner = &ac * &a_inner;
            b_inner = &ac * &b_inner + &bc;
        }

        // One position tick, state q = [x, Ic, Ip, e_prev], inputs [sp, ff]:
        //   e = sp - theta_rot;  Ip' = Ip + Ki Tp e;  e_prev' = e
        //   i* = Kp e + Ip' + Kd (e - e_prev)/Tp + ff = kpid e + Ip - (Kd/Tp) e_prev + ff
        let kpid = g.position_kp + g.position_ki * tp + g.position_kd / tp;
        // i* as a row over [q; sp; ff]
        let mut istar = RowDVector::<f64>::zeros(NQ + 2);
        istar[state::THETA_ROT] = -kpid;
        istar[IP] = 1.0;
        istar[EPREV] = -g.position_kd / tp;
        istar[NQ] = kpid;
        istar[NQ + 1] = 1.0;
        let mut step = DMatrix::<f64>::zeros(NQ, NQ + 2);
        // [x, Ic]' = Ai [x, Ic] + bi i*
        for i in 0..8 {
            for j in 0..8 {
                step[(i, j)] = a_inner[(i, j)];
            }
            for j in 0..NQ + 2 {
                step[(i, j)] += b_inner[i] * istar[j];
            }
        }
        // Ip' = Ip + Ki Tp (sp - theta_rot)
        step[(IP, IP)] = 1.0;
        step[(IP, state::THETA_ROT)] = -g.position_ki * tp;
        step[(IP, NQ)] = g.position_ki * tp;
        // e_prev' = sp - theta_rot
        step[(EPREV, state::THETA_ROT)] = -1.0;
        step[(EPREV, NQ)] = 1.0;
        let a_cl = step.columns(0, NQ).into_owned();
        let b_cl = step.columns(NQ, 2).into_owned();

        // The 10 ms lift over w = [q (10), r_last, s_last, r] (r: the new sample, steering rad).
        // Push: s = (ratio r - r_last)/T, a = (s - s_last)/T (or s/T), ff = Kv s + Ka a.
        let mut s_row = RowDVector::<f64>::zeros(NW);
        s_row[NS] = ratio / t;
        s_row[RLAST] = -1.0 / t;
        let mut a_row = &s_row / t;
        if accel_ff == AccelFeedforward::ChangeOfSlope {
            a_row[SLAST] -= 1.0 / t;
        }
        let ff_row = &s_row * g.ff_velocity + &a_row * g.ff_acceleration;
        let b_sp = b_cl.column(0).into_owned();
        let b_ff = b_cl.column(1).into_owned();
        let mut q = DMatrix::<f64>::zeros(NQ, NW);
        for i in 0..NQ {
            q[(i, i)] = 1.0;
        }
        let mut q_after = Vec::with_capacity(n_p);
        for m in 0..n_p {
            // sp = r_last + (ratio r - r_last) m / 20
            let frac = m as f64 / n_p as f64;
            let mut sp_row = RowDVector::<f64>::zeros(NW);
            sp_row[RLAST] = 1.0 - frac;
            sp_row[NS] = ratio * frac;
            q = &a_cl * &q + &b_sp * &sp_row + &b_ff * &ff_row;
            q_after.push(q.clone());
        }
        let mut lift = DMatrix::<f64>::zeros(NS, NW);
        lift.rows_mut(0, NQ).copy_from(&q);
        lift[(RLAST, NS)] = ratio;
        lift.row_mut(SLAST).copy_from(&s_row);
        let phi = lift.columns(0, NS).into_owned();
        let gamma = lift.column(NS).into_owned();

        Ok(LinearModel {
            params,
            gains: g,
            accel_ff,
            ratio,
            tp,
            a_inner,
            b_inner,
            a_cl,
            b_cl,
            phi,
            gamma,
            q_after,
        })
    }

    pub fn params(&self) -> &PlantParams {
        &self.params
    }

    pub fn gains(&self) -> &ModelGains {
        &self.gains
    }

    pub fn accel_feedforward(&self) -> AccelFeedforward {
        self.accel_ff
    }

    /// The 10 ms lift `(Phi, Gamma)`, state `[x (7), Ic, Ip, e_prev, r_last, s_last]`.
    pub fn lifted(&self) -> (&DMatrix<f64>, &DVector<f64>) {
        (&self.phi, &self.gamma)
    }

    /// The 2 kHz closed loop `(Acl, Bcl)`, state `[x (7), Ic, Ip, e_prev]`, inputs `[sp, ff]`.
    pub fn position_rate_closed_loop(&self) -> (&DMatrix<f64>, &DMatrix<f64>) {
        (&self.a_cl, &self.b_cl)
    }

    /// The output row over `q` for an angle.
    fn output_row(&self, output: Output) -> RowDVector<f64> {
        let mut c = RowDVector::<f64>::zeros(NQ);
        match output {
            Output::Column => c[state::THETA_BS] = self.params.screw_to_pinion(),
            Output::Motor => c[state::THETA_ROT] = 1.0 / self.ratio,
        }
        c
    }

    /// The periodic steady state per unit reference `r[n] = e^{j w n T}`: the angle after each
    /// of the 20 position ticks of a period (`g_m` of the module doc), steering rad per rad.
    pub fn per_tick_response(&self, f_hz: f64, output: Output) -> Vec<Complex<f64>> {
        let t = 1.0 / REFERENCE_HZ as f64;
        let z = Complex::from_polar(1.0, TAU * f_hz * t);
        let mut m =
            DMatrix::<Complex<f64>>::from_fn(NS, NS, |i, j| Complex::new(-self.phi[(i, j)], 0.0));
        for i in 0..NS {
            m[(i, i)] += z;
        }
        let rhs = DVector::<Complex<f64>>::from_fn(NS, |i, _| Complex::new(self.gamma[i], 0.0));
        let s = m
            .lu()
            .solve(&rhs)
            .unwrap_or_else(|| DVector::from_element(NS, Complex::new(f64::NAN, f64::NAN)));
        let mut w = DVector::<Complex<f64>>::zeros(NW);
        w.rows_mut(0, NS).copy_from(&s);
        w[NS] = Complex::new(1.0, 0.0);
        let c = self.output_row(output);
        self.q_after
            .iter()
            .map(|q| {
                let row = &c * q;
                (0..NW).map(|j| w[j] * row[j]).sum()
            })
            .collect()
    }

    /// The response as host-sim's log at `log_rate_hz` and the H1 estimator see it (module
    /// doc): complex, per unit reference at the wheel.
    pub fn response(
        &self,
        f_hz: f64,
        output: Output,
        log_rate_hz: u32,
    ) -> Result<Complex<f64>, ModelError> {
        if log_rate_hz == 0 || !POSITION_LOOP_HZ.is_multiple_of(log_rate_hz) {
            return Err(ModelError::LogRate { hz: log_rate_hz });
        }
        let every = (POSITION_LOOP_HZ / log_rate_hz) as usize;
        let n_p = POSITION_TICKS_PER_REFERENCE as usize;
        let g = self.per_tick_response(f_hz, output);
        // A row at the end of every log interval (`sim.rs`): after ticks j = every - 1,
        // 2 every - 1, ... over lcm(20, every) ticks, with the angles after tick j's current
        // ticks and the reference of its period; row j sits at m = j mod 20 of its period.
        let span = lcm(n_p, every);
        let w = TAU * f_hz;
        let mut num = Complex::new(0.0, 0.0);
        let mut den = Complex::new(0.0, 0.0);
        for j in ((every - 1)..span).step_by(every) {
            let m = j % n_p;
            let e = Complex::from_polar(1.0, -w * m as f64 * self.tp);
            num += g[m] * e;
            den += e;
        }
        Ok(num / den)
    }

    /// [`LinearModel::response`] over a grid, as magnitude (dB) and unwrapped phase (deg).
    pub fn bode(
        &self,
        freq_hz: &[f64],
        output: Output,
        log_rate_hz: u32,
    ) -> Result<crate::analysis::FrequencyResponse, ModelError> {
        let mut fr = crate::analysis::FrequencyResponse::default();
        let mut last_phase: Option<f64> = None;
        for &f in freq_hz {
            let h = self.response(f, output, log_rate_hz)?;
            let mut p = h.arg().to_degrees();
            if let Some(prev) = last_phase {
                p += 360.0 * ((prev - p) / 360.0).round();
            }
            last_phase = Some(p);
            fr.freq_hz.push(f);
            fr.magnitude_db.push(20.0 * h.norm().log10());
            fr.phase_deg.push(p);
            fr.coherence.push(1.0);
        }
        Ok(fr)
    }

    /// The -3 dB bandwidth of the column response (as logged at `log_rate_hz`), found on a
    /// 0.01 Hz grid from `f_min_hz` and refined by bisection; `None` below `f_max_hz`.
    pub fn bandwidth_hz(&self, f_min_hz: f64, f_max_hz: f64, log_rate_hz: u32) -> Option<f64> {
        let db = |f: f64| {
            self.response(f, Output::Column, log_rate_hz)
                .map(|h| 20.0 * h.norm().log10())
                .unwrap_or(f64::NAN)
        };
        let mut lo = f_min_hz;
        if db(lo) < -3.0 {
            return Some(lo);
        }
        let step = 0.01;
        while lo < f_max_hz {
            let hi = (lo + step).min(f_max_hz);
            if db(hi) < -3.0 {
                return Some(bisect(lo, hi, |f| db(f) + 3.0));
            }
            lo = hi;
        }
        None
    }

    /// Closed-loop poles: the 2 kHz closed loop's eigenvalues as `s = ln(lambda) / Tp`,
    /// sorted by |s|. (The 10 ms lift has these to the 20th power, plus the interpolator's two
    /// at 0: it is outside the loop.)
    pub fn closed_loop_poles(&self) -> Vec<Pole> {
        let eig = self.a_cl.complex_eigenvalues();
        let mut poles: Vec<Pole> = eig
            .iter()
            .map(|l| {
                let s = l.ln() / self.tp;
                let wn = s.norm();
                Pole {
                    re: s.re,
                    im: s.im,
                    wn,
                    f_hz: wn / TAU,
                    zeta: if wn > 0.0 { -s.re / wn } else { f64::NAN },
                    z_magnitude: l.norm(),
                }
            })
            .collect();
        poles.sort_by(|a, b| a.wn.total_cmp(&b.wn).then(a.im.total_cmp(&b.im)));
        poles
    }

    /// Whether every closed-loop eigenvalue lies inside the unit circle.
    pub fn is_stable(&self) -> bool {
        self.closed_loop_poles().iter().all(|p| p.z_magnitude < 1.0)
    }

    /// ECU mode's loop transfer (`steering_ecu::ecu_mode`), broken at the current set-point:
    /// the same PID and plant, with the proportional and integral column terms feeding the
    /// pinion angle back into the set-point (`sp += G (Kc + (Tp/tau)/(1 - 1/z)) (r - delta_P)`),
    /// and the D term on the motor speed alone (Hall edge timing, linearised as the exact
    /// speed's backward difference):
    ///
    /// ```text
    ///   L = (Kp + Ki Tp/(1 - 1/z)) (P_m + G (Kc + (Tp/tau)/(1 - 1/z)) P_c) + Kd (1 - 1/z)/Tp P_m
    /// ```
    ///
    /// `P_m = theta_rot / i*`, `P_c = delta_P / i*`. Linearised: the column encoder's dead band
    /// and 500 Hz sampling are left out (the column term acts every tick), and the inverse belt
    /// model and the model feedforward are outside the loop.
    pub fn ecu_loop_transfer(&self, f_hz: f64, tuning: &EcuTuning) -> Complex<f64> {
        let z = Complex::from_polar(1.0, TAU * f_hz * self.tp);
        let (p_m, p_c) = self.plant_per_current(z);
        let zi = z.inv();
        let one = Complex::new(1.0, 0.0);
        let pi = self.gains.position_kp + (one - zi).inv() * (self.gains.position_ki * self.tp);
        let column = tuning.column_gain as f64
            + (one - zi).inv() * (self.tp / tuning.column_time_constant_s as f64);
        pi * (p_m + column * self.ratio * p_c)
            + (one - zi) * (self.gains.position_kd / self.tp) * p_m
    }

    /// `(theta_rot, delta_P)` per unit current set-point held over position ticks, at `z`.
    fn plant_per_current(&self, z: Complex<f64>) -> (Complex<f64>, Complex<f64>) {
        let n = self.a_inner.nrows();
        let mut m =
            DMatrix::<Complex<f64>>::from_fn(n, n, |i, j| Complex::new(-self.a_inner[(i, j)], 0.0));
        for i in 0..n {
            m[(i, i)] += z;
        }
        let rhs = DVector::<Complex<f64>>::from_fn(n, |i, _| Complex::new(self.b_inner[i], 0.0));
        let nan = Complex::new(f64::NAN, f64::NAN);
        m.lu().solve(&rhs).map_or((nan, nan), |x| {
            (
                x[state::THETA_ROT],
                x[state::THETA_BS] * self.params.screw_to_pinion(),
            )
        })
    }

    /// [`LinearModel::margins`] of ECU mode's loop ([`LinearModel::ecu_loop_transfer`]).
    pub fn ecu_margins(&self, tuning: &EcuTuning) -> Margins {
        self.margins_of(|f| self.ecu_loop_transfer(f, tuning))
    }

    /// The loop transfer `L(e^{j w Tp}) = C P` with the loop broken at the current set-point.
    pub fn loop_transfer(&self, f_hz: f64) -> Complex<f64> {
        let z = Complex::from_polar(1.0, TAU * f_hz * self.tp);
        let (p, _) = self.plant_per_current(z);
        let zi = z.inv();
        let one = Complex::new(1.0, 0.0);
        let c = self.gains.position_kp
            + (one - zi).inv() * (self.gains.position_ki * self.tp)
            + (one - zi) * (self.gains.position_kd / self.tp);
        c * p
    }

    /// Gain and phase margins of the position loop (broken at `i*`), from 0.01 Hz to the
    /// 1 kHz Nyquist limit of the position loop.
    pub fn margins(&self) -> Margins {
        self.margins_of(|f| self.loop_transfer(f))
    }

    /// Margins of any loop transfer over the same grid.
    fn margins_of(&self, loop_transfer: impl Fn(f64) -> Complex<f64>) -> Margins {
        let nyquist = POSITION_LOOP_HZ as f64 / 2.0;
        let n = 4000;
        let grid: Vec<f64> = (0..=n)
            .map(|k| 0.01 * (nyquist * 0.999 / 0.01).powf(k as f64 / n as f64))
            .collect();
        let l: Vec<Complex<f64>> = grid.iter().map(|&f| loop_transfer(f)).collect();
        // Unwrapped phase, starting on the branch (-270, 90] (an integrator and the free
        // rigid body put it near -180 at low frequency).
        let mut phase = Vec::with_capacity(l.len());
        for (k, h) in l.iter().enumerate() {
            let mut p = h.arg().to_degrees();
            if k == 0 {
                if p > 90.0 {
                    p -= 360.0;
                }
            } else {
                let prev: f64 = phase[k - 1];
                p += 360.0 * ((prev - p) / 360.0).round();
            }
            phase.push(p);
        }
        let mag_db: Vec<f64> = l.iter().map(|h| 20.0 * h.norm().log10()).collect();
        let unwrapped_phase = |f: f64, near: f64| {
            let p = loop_transfer(f).arg().to_degrees();
            p + 360.0 * ((near - p) / 360.0).round()
        };
        let mut out = Margins {
            gain_margin_db: None,
            phase_crossover_hz: None,
            phase_margin_deg: None,
            gain_crossover_hz: None,
            phase_crossovers: Vec::new(),
            gain_crossovers: Vec::new(),
        };
        for k in 1..grid.len() {
            let (f0, f1) = (grid[k - 1], grid[k]);
            // |L| = 1
            if (mag_db[k - 1] > 0.0) != (mag_db[k] > 0.0) {
                let f = bisect(f0, f1, |f| 20.0 * loop_transfer(f).norm().log10());
                let p = unwrapped_phase(f, phase[k]);
                let pm = wrap_deg(180.0 + p);
                out.gain_crossovers.push(PhaseCrossing {
                    f_hz: f,
                    margin_deg: pm,
                });
            }
            // arg L = -180 (mod 360)
            let level = -180.0 + 360.0 * ((phase[k - 1] + 180.0) / 360.0).floor();
            for lv in [level, level + 360.0] {
                if (phase[k - 1] - lv) * (phase[k] - lv) < 0.0 {
                    let near = phase[k];
                    let f = bisect(f0, f1, |f| unwrapped_phase(f, near) - lv);
                    out.phase_crossovers.push(GainCrossing {
                        f_hz: f,
                        margin_db: -20.0 * loop_transfer(f).norm().log10(),
                    });
                }
            }
        }
        if let Some(pm) = out
            .gain_crossovers
            .iter()
            .min_by(|a, b| a.margin_deg.total_cmp(&b.margin_deg))
        {
            out.phase_margin_deg = Some(pm.margin_deg);
            out.gain_crossover_hz = Some(pm.f_hz);
        }
        if let Some(gm) = out
            .phase_crossovers
            .iter()
            .filter(|c| c.margin_db > 0.0)
            .min_by(|a, b| a.margin_db.total_cmp(&b.margin_db))
        {
            out.gain_margin_db = Some(gm.margin_db);
            out.phase_crossover_hz = Some(gm.f_hz);
        }
        out
    }
}

fn wrap_deg(p: f64) -> f64 {
    let w = p - 360.0 * (p / 360.0).round();
    if w <= -180.0 { w + 360.0 } else { w }
}

fn gcd(a: usize, b: usize) -> usize {
    if b == 0 { a } else { gcd(b, a % b) }
}

fn lcm(a: usize, b: usize) -> usize {
    a / gcd(a, b) * b
}

/// A root of `g` in `[lo, hi]` where it changes sign, by 60 halvings.
fn bisect(mut lo: f64, mut hi: f64, g: impl Fn(f64) -> f64) -> f64 {
    let glo = g(lo);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if (g(mid) > 0.0) == (glo > 0.0) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Steady-state demand at the motor for a sinusoidal pinion angle.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Demand {
    pub f_hz: f64,
    pub pinion_amplitude_deg: f64,
    /// Current amplitude, A.
    pub current_a: f64,
    /// Terminal voltage amplitude, V.
    pub voltage_v: f64,
    /// The largest pinion amplitude within the limits at this frequency, deg.
    pub largest_amplitude_deg: f64,
    /// Which limit sets `largest_amplitude_deg`.
    pub limited_by: LimitedBy,
}

/// Which of the two limits is reached first.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LimitedBy {
    Current,
    Voltage,
}

/// What the plant allows whatever the controller: the current and voltage needed for
/// a sinusoidal pinion angle, from the continuous plant of eqs. 1-8.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhysicalLimit {
    pub params: PlantParams,
    /// A (paper: 20 A).
    pub current_limit_a: f64,
    /// V (paper: the 24 V battery).
    pub voltage_limit_v: f64,
}

/// `10^(-3/20)`: the amplitude ratio at -3 dB, as `analysis::bandwidth_hz` uses it.
pub const MINUS_3_DB: f64 = 0.707_945_784_384_137_9;

impl PhysicalLimit {
    /// The paper plant with the 20 A / 24 V limits of section 3.3.
    pub fn paper() -> Self {
        PhysicalLimit {
            params: PlantParams::PAPER,
            current_limit_a: steering_ecu::paper_mode::CURRENT_LIMIT.0 as f64,
            voltage_limit_v: steering_ecu::paper_mode::VOLTAGE_LIMIT.0 as f64,
        }
    }

    /// The same plant driven by a saturated (bang-bang) controller: a current or voltage clipped
    /// at +-L is at most a square wave, whose fundamental is `4 L / pi`. A chirp's H1 estimate
    /// reads the fundamental, so this is the upper bound a saturating controller can approach
    /// (ECU mode at 10 deg is saturated 30 % of the time): 25.5 A and 30.6 V on the paper's
    /// 20 A / 24 V. It is an upper bound: current and voltage cannot both be square at once.
    pub fn saturated(&self) -> Self {
        let k = 4.0 / std::f64::consts::PI;
        PhysicalLimit {
            current_limit_a: k * self.current_limit_a,
            voltage_limit_v: k * self.voltage_limit_v,
            ..*self
        }
    }

    /// `(current A, voltage V)` amplitudes per radian of pinion amplitude at `f_hz`.
    pub fn per_pinion_rad(&self, f_hz: f64) -> (f64, f64) {
        let (a, b) = self.params.electromechanical_state_space();
        let jw = Complex::new(0.0, TAU * f_hz);
        let m = SMatrix::<Complex<f64>, 7, 7>::from_fn(|i, j| {
            let d = if i == j { jw } else { Complex::new(0.0, 0.0) };
            d - Complex::new(a[(i, j)], 0.0)
        });
        let rhs = SVector::<Complex<f64>, 7>::from_fn(|i, _| Complex::new(b[i], 0.0));
        let Some(x) = m.lu().solve(&rhs) else {
            return (f64::NAN, f64::NAN);
        };
        // per volt: current and pinion angle
        let pinion = x[state::THETA_BS] * self.params.screw_to_pinion();
        let volts_per_rad = 1.0 / pinion.norm();
        (x[state::CURRENT].norm() * volts_per_rad, volts_per_rad)
    }

    /// Current and voltage for `pinion_amplitude_deg` at `f_hz`, and the largest amplitude
    /// within the limits there.
    pub fn demand(&self, f_hz: f64, pinion_amplitude_deg: f64) -> Demand {
        let (i, v) = self.per_pinion_rad(f_hz);
        let a = pinion_amplitude_deg.to_radians();
        Demand {
            f_hz,
            pinion_amplitude_deg,
            current_a: i * a,
            voltage_v: v * a,
            largest_amplitude_deg: self.largest_amplitude_deg(f_hz),
            limited_by: if self.current_limit_a / i <= self.voltage_limit_v / v {
                LimitedBy::Current
            } else {
                LimitedBy::Voltage
            },
        }
    }

    /// The largest pinion amplitude the motor can hold at `f_hz` within both limits, deg.
    pub fn largest_amplitude_deg(&self, f_hz: f64) -> f64 {
        let (i, v) = self.per_pinion_rad(f_hz);
        (self.current_limit_a / i)
            .min(self.voltage_limit_v / v)
            .to_degrees()
    }

    /// The highest frequency at which a sweep of `amplitude_deg` can still reach -3 dB
    /// (`10^(-3/20) amplitude_deg` at the pinion): the bound on any controller's -3 dB
    /// bandwidth on this plant. Searched up to 50 Hz (the reference's Nyquist limit); `None`
    /// if it is reachable all the way there.
    pub fn bandwidth_bound_hz(&self, amplitude_deg: f64) -> Option<f64> {
        let need = MINUS_3_DB * amplitude_deg.abs();
        let reachable = |f: f64| self.largest_amplitude_deg(f) - need;
        let f_max = REFERENCE_HZ as f64 / 2.0;
        // Scan down from the top: the last frequency where it is reachable.
        let step = 0.01;
        let mut hi = f_max;
        if reachable(hi) >= 0.0 {
            return None;
        }
        while hi > step {
            let lo = hi - step;
            if reachable(lo) >= 0.0 {
                return Some(bisect(lo, hi, reachable));
            }
            hi = lo;
        }
        Some(0.0)
    }
}

/// Frequencies `f_lo..=f_hi` Hz, `n` points spaced logarithmically.
pub fn log_grid(f_lo: f64, f_hi: f64, n: usize) -> Vec<f64> {
    let n = n.max(2);
    (0..n)
        .map(|k| f_lo * (f_hi / f_lo).powf(k as f64 / (n - 1) as f64))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper() -> LinearModel {
        LinearModel::new(PlantParams::PAPER, &EposGains::PAPER).expect("paper model")
    }

    #[test]
    fn static_gain_is_one_for_column_and_motor() {
        let m = paper();
        for out in [Output::Column, Output::Motor] {
            for rate in [100, 1000, 2000] {
                let h = m.response(1e-4, out, rate).unwrap();
                assert!((h.norm() - 1.0).abs() < 1e-4, "{out:?} {rate}: {h}");
                assert!(h.arg().to_degrees().abs() < 0.1, "{out:?} {rate}: {h}");
            }
        }
    }

    #[test]
    fn paper_loop_is_stable() {
        let m = paper();
        assert!(m.is_stable(), "{:?}", m.closed_loop_poles());
    }

    #[test]
    fn the_10ms_lift_has_the_2khz_poles_to_the_20th_and_the_interpolator_at_zero() {
        let m = paper();
        let (phi, _) = m.lifted();
        let mut lifted: Vec<Complex<f64>> = phi.complex_eigenvalues().iter().copied().collect();
        let mut fast: Vec<Complex<f64>> = m
            .a_cl
            .complex_eigenvalues()
            .iter()
            .map(|l| l.powu(POSITION_TICKS_PER_REFERENCE))
            .collect();
        fast.push(Complex::new(0.0, 0.0));
        fast.push(Complex::new(0.0, 0.0));
        // Match each lifted eigenvalue to the nearest expected one.
        for l in lifted.drain(..) {
            let (k, d) = fast
                .iter()
                .enumerate()
                .map(|(k, e)| (k, (e - l).norm()))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap();
            assert!(d < 1e-6, "{l} unmatched (nearest {})", fast[k]);
            fast.remove(k);
        }
    }

    #[test]
    fn loop_transfer_gives_the_state_space_sensitivity() {
        // The sensitivity at the break point, 1 / (1 + L), equals the state-space closed loop
        // from a disturbance added to i* to the applied i*.
        let m = paper();
        for f in [0.3, 2.0, 7.0, 40.0] {
            let l = m.loop_transfer(f);
            // S = 1 / (1 + L) from state space: inject d at i*, read i*_c.
            let z = Complex::from_polar(1.0, TAU * f * m.tp);
            // state-space closed loop with sp = 0, ff = d: i*_applied = i*_c + d
            // i*_c = kpid (-theta) + Ip - Kd/Tp e_prev  ->  (i*_c + d) / d = S
            let n = NQ;
            let mut a =
                DMatrix::<Complex<f64>>::from_fn(n, n, |i, j| Complex::new(-m.a_cl[(i, j)], 0.0));
            for i in 0..n {
                a[(i, i)] += z;
            }
            let rhs = DVector::<Complex<f64>>::from_fn(n, |i, _| Complex::new(m.b_cl[(i, 1)], 0.0));
            let q = a.lu().solve(&rhs).unwrap();
            let g = m.gains;
            let kpid = g.position_kp + g.position_ki * m.tp + g.position_kd / m.tp;
            let icmd = -kpid * q[state::THETA_ROT] + q[IP] - q[EPREV] * (g.position_kd / m.tp);
            // One tick's integrator and difference act on this tick's theta: the applied
            // current is i*_c + d with q the state at the start of the tick.
            let s_ss = icmd + Complex::new(1.0, 0.0);
            let s_l = (Complex::new(1.0, 0.0) + l).inv();
            assert!(
                (s_ss - s_l).norm() < 1e-6 * s_l.norm().max(1.0),
                "{f} Hz: {s_ss} vs {s_l}"
            );
        }
    }

    #[test]
    fn old_accel_feedforward_changes_the_response() {
        let fixed = paper();
        let old = LinearModel::with_accel_feedforward(
            PlantParams::PAPER,
            &EposGains::PAPER,
            AccelFeedforward::SlopeOverPeriod,
        )
        .unwrap();
        let db =
            |m: &LinearModel, f| 20.0 * m.response(f, Output::Column, 1000).unwrap().norm().log10();
        // At 3 Hz the defect adds about +-several dB; at 0.05 Hz neither differs from 1.
        assert!((db(&fixed, 3.0) - db(&old, 3.0)).abs() > 1.0);
        assert!((db(&fixed, 0.05) - db(&old, 0.05)).abs() < 0.1);
    }

    #[test]
    fn issue_14_table() {
        // f, current A, voltage V, largest amplitude deg, for 7.07 deg of pinion.
        let table = [
            (3.0, 11.3, 17.4, 9.75),
            (4.0, 14.5, 25.9, 6.54),
            (5.0, 20.8, 36.5, 4.65),
            (8.0, 82.8, 83.1, 1.71),
        ];
        let lim = PhysicalLimit::paper();
        for (f, i, v, amax) in table {
            let d = lim.demand(f, 7.07);
            assert!((d.current_a - i).abs() < 0.06 + 0.005 * i, "{f} Hz: {d:?}");
            assert!((d.voltage_v - v).abs() < 0.06 + 0.005 * v, "{f} Hz: {d:?}");
            assert!(
                (d.largest_amplitude_deg - amax).abs() < 0.02,
                "{f} Hz: {d:?}"
            );
        }
        // The bound is where the largest amplitude falls to -3 dB of the sweep's.
        for (amplitude, coarse_table_hz) in [(10.0, 3.8), (2.0, 8.6)] {
            let b = lim
                .bandwidth_bound_hz(amplitude)
                .expect("bounded below 50 Hz");
            let at = lim.largest_amplitude_deg(b);
            assert!(
                (at - MINUS_3_DB * amplitude).abs() < 1e-6,
                "{b} Hz: {at} deg"
            );
            assert!(lim.largest_amplitude_deg(b + 0.05) < MINUS_3_DB * amplitude);
            assert!(lim.largest_amplitude_deg(b - 0.05) > MINUS_3_DB * amplitude);
            // A coarse table of the plant reads "about 3.8 Hz" and "about 8.6 Hz"; the
            // crossings are 3.79 Hz (voltage-bound) and 8.47 Hz (current-bound).
            assert!((b - coarse_table_hz).abs() < 0.2, "{amplitude} deg: {b} Hz");
        }
    }

    #[test]
    fn refuses_a_log_rate_that_does_not_divide_the_position_loop() {
        let m = paper();
        assert!(m.response(1.0, Output::Column, 300).is_err());
        assert!(m.response(1.0, Output::Column, 0).is_err());
        // 250 Hz (every 8 ticks, not a divisor of 20) is allowed and finite.
        assert!(
            m.response(1.0, Output::Column, 250)
                .unwrap()
                .norm()
                .is_finite()
        );
    }
}
