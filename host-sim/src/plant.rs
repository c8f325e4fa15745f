//! The paper's steering actuator as a linear plant: the winding (eq. 1-3) and the 3-DOF
//! mechanics (eqs. 5-8), with the parameters of Tables 1, 2 and 4 as defaults.
//!
//! Two printing errors of the paper are corrected (see `host-sim/MODEL.md`):
//! the belt factor in eqs. 5-6 is 1/2 (the nut turns at half the motor speed), and the
//! torsion-bar terms of eq. 6 carry (tauBS/tauP)^2. With both, the mechanical poles are
//! 0, -334 rad/s and complex pairs of magnitude 30.6 and 138.8 rad/s, against the paper's
//! 0, 334, 30.9 and 131 rad/s (section 4.3); `poles_match_the_paper` checks it.
//!
//! State `x = [i_a, theta_rot, w_rot, theta_BS, w_BS, delta_SW, w_SW]`, input the terminal
//! voltage. Between current-loop ticks the voltage is held (the PWM average), so the exact
//! zero-order-hold discretisation `x[k+1] = Ad x[k] + Bd v[k]` is used: no integration error
//! at any step size, and 56 multiply-adds per tick.

use nalgebra::{Complex, SMatrix, SVector};

/// Every physical parameter of the plant, SI units.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlantParams {
    // Table 1: motor
    /// Terminal resistance, ohm
    pub ra: f64,
    /// Terminal inductance, H
    pub la: f64,
    /// Torque constant, Nm/A
    pub kt: f64,
    /// Back-EMF constant, V/(rad/s)
    pub ke: f64,
    /// Motor viscous loss (eq. 4), Nm/(rad/s)
    pub r: f64,
    // Table 2: mechanics
    /// Rotor inertia, kg m^2
    pub j_rot: f64,
    /// Ball-screw mass, kg
    pub m_bs: f64,
    /// Rack mass, kg
    pub m_r: f64,
    /// Motor turns per nut turn (Table 2 "tauB = 2"; enters eqs. 5-6 as 1/belt_reduction)
    pub belt_reduction: f64,
    /// Ball-screw lead / 2 pi, m/rad
    pub tau_bs: f64,
    /// Pinion C-factor / 2 pi, m/rad
    pub tau_p: f64,
    /// Rack displacement to wheel toe angle, rad/m
    pub tau_r: f64,
    // Table 4: identified
    /// Ball-screw inertia, kg m^2
    pub j_bs: f64,
    /// Steering wheel inertia, kg m^2
    pub j_sw: f64,
    /// Wheel inertia (about the kingpin), kg m^2
    pub j_w: f64,
    /// Belt stiffness, Nm/rad
    pub k_b: f64,
    /// Belt damping, Nm/(rad/s)
    pub beta_b: f64,
    /// Ball-screw damping, Nm/(rad/s)
    pub beta_bs: f64,
    /// Torsion-bar (column) stiffness, Nm/rad
    pub k_tb: f64,
    /// Torsion-bar damping, Nm/(rad/s)
    pub beta_tb: f64,
    /// Steering-wheel damping, Nm/(rad/s)
    pub beta_sw: f64,
}

impl Default for PlantParams {
    fn default() -> Self {
        Self::PAPER
    }
}

impl PlantParams {
    /// The state at rest at a steering angle: no current, no speed, belt and column unloaded
    /// (motor, nut and column all at the angle through the gearing).
    pub fn at_rest(&self, column_rad: f64) -> [f64; 7] {
        let theta_bs = column_rad / self.screw_to_pinion();
        let mut x = [0.0; 7];
        x[state::THETA_BS] = theta_bs;
        x[state::THETA_ROT] = theta_bs * self.belt_reduction;
        x[state::DELTA_SW] = column_rad;
        x
    }

    /// Tables 1, 2 and 4 of the paper.
    pub const PAPER: PlantParams = PlantParams {
        ra: 0.293,
        la: 0.279e-3,
        kt: 52.5e-3,
        ke: 52.5e-3,
        r: 5.78e-5,
        j_rot: 0.81e-4,
        m_bs: 0.171,
        m_r: 6.5e-2,
        belt_reduction: 2.0,
        tau_bs: 3.183e-4,
        tau_p: 1.36e-2,
        tau_r: 19.4,
        j_bs: 6.5e-6,
        j_sw: 3.3e-3,
        j_w: 2.65,
        k_b: 0.29,
        beta_b: 1.7e-3,
        beta_bs: 1.34e-2,
        k_tb: 164.75,
        beta_tb: 0.0,
        beta_sw: 1.59,
    };

    /// Equivalent inertia at the ball screw, kg m^2 (eq. 8).
    pub fn j_bs_equivalent(&self) -> f64 {
        self.j_bs
            + (self.m_r + self.m_bs) * self.tau_bs.powi(2)
            + self.j_w * self.tau_bs.powi(2) * self.tau_r.powi(2)
    }

    /// Pinion angle per screw angle (eq. 7's tauBS/tauP).
    pub fn screw_to_pinion(&self) -> f64 {
        self.tau_bs / self.tau_p
    }

    /// Motor radians per pinion radian with the belt unloaded.
    pub fn motor_per_pinion(&self) -> f64 {
        self.belt_reduction / self.screw_to_pinion()
    }

    /// Names and values of the nine parameters of Table 4, in the paper's order.
    pub fn identified(&self) -> [(&'static str, f64); 9] {
        [
            ("j_bs", self.j_bs),
            ("j_sw", self.j_sw),
            ("j_w", self.j_w),
            ("k_b", self.k_b),
            ("beta_b", self.beta_b),
            ("beta_bs", self.beta_bs),
            ("k_tb", self.k_tb),
            ("beta_tb", self.beta_tb),
            ("beta_sw", self.beta_sw),
        ]
    }

    /// Mass, damping and stiffness matrices of eqs. 5-7 in q = [theta_rot, theta_BS, delta_SW].
    fn mck(&self) -> (SMatrix<f64, 3, 3>, SMatrix<f64, 3, 3>, SMatrix<f64, 3, 3>) {
        // Printing error 1: the belt factor is the nut/motor speed ratio, 1/2.
        let tb = 1.0 / self.belt_reduction;
        // Printing error 2: both torsion-bar terms of eq. 6 carry g = tauBS/tauP.
        let g = self.screw_to_pinion();
        let m = SMatrix::<f64, 3, 3>::from_diagonal(&SVector::<f64, 3>::new(
            self.j_rot,
            self.j_bs_equivalent(),
            self.j_sw,
        ));
        #[rustfmt::skip]
        let c = SMatrix::<f64, 3, 3>::new(
            self.r + self.beta_b * tb * tb, -self.beta_b * tb, 0.0,
            -self.beta_b * tb, self.beta_bs + self.beta_b + self.beta_tb * g * g, -self.beta_tb * g,
            0.0, -self.beta_tb * g, self.beta_sw + self.beta_tb,
        );
        #[rustfmt::skip]
        let k = SMatrix::<f64, 3, 3>::new(
            self.k_b * tb * tb, -self.k_b * tb, 0.0,
            -self.k_b * tb, self.k_b + self.k_tb * g * g, -self.k_tb * g,
            0.0, -self.k_tb * g, self.k_tb,
        );
        (m, c, k)
    }

    /// The mechanical state matrix (6 x 6, state [theta_rot, w_rot, theta_BS, w_BS, delta_SW,
    /// w_SW]) and its input column for the motor torque: the paper's `x' = A x + B Tm`.
    pub fn mechanical_state_space(&self) -> (SMatrix<f64, 6, 6>, SVector<f64, 6>) {
        let (m, c, k) = self.mck();
        let m_inv = SMatrix::<f64, 3, 3>::from_diagonal(&m.diagonal().map(|d| 1.0 / d));
        let mk = m_inv * k;
        let mc = m_inv * c;
        let mut a = SMatrix::<f64, 6, 6>::zeros();
        let mut b = SVector::<f64, 6>::zeros();
        for i in 0..3 {
            a[(2 * i, 2 * i + 1)] = 1.0;
            for j in 0..3 {
                a[(2 * i + 1, 2 * j)] = -mk[(i, j)];
                a[(2 * i + 1, 2 * j + 1)] = -mc[(i, j)];
            }
        }
        b[1] = 1.0 / self.j_rot;
        (a, b)
    }

    /// The full state matrix with the winding (7 x 7), input the terminal voltage.
    pub fn electromechanical_state_space(&self) -> (SMatrix<f64, 7, 7>, SVector<f64, 7>) {
        let (am, bm) = self.mechanical_state_space();
        let mut a = SMatrix::<f64, 7, 7>::zeros();
        a.fixed_view_mut::<6, 6>(1, 1).copy_from(&am);
        // eq. 1: La di/dt = v - Ra i - ke w_rot
        a[(0, 0)] = -self.ra / self.la;
        a[(0, 2)] = -self.ke / self.la;
        // eq. 3: Tm = kt i drives the motor row
        for row in 0..6 {
            a[(row + 1, 0)] = bm[row] * self.kt;
        }
        let mut b = SVector::<f64, 7>::zeros();
        b[0] = 1.0 / self.la;
        (a, b)
    }

    /// Eigenvalues of the mechanical model (rad/s), sorted by magnitude.
    pub fn mechanical_poles(&self) -> Vec<Complex<f64>> {
        let (a, _) = self.mechanical_state_space();
        sorted_by_magnitude(a.complex_eigenvalues().iter().copied().collect())
    }

    /// Eigenvalues with the winding included (rad/s), sorted by magnitude.
    pub fn electromechanical_poles(&self) -> Vec<Complex<f64>> {
        let (a, _) = self.electromechanical_state_space();
        sorted_by_magnitude(a.complex_eigenvalues().iter().copied().collect())
    }
}

fn sorted_by_magnitude(mut poles: Vec<Complex<f64>>) -> Vec<Complex<f64>> {
    poles.sort_by(|a, b| a.norm().total_cmp(&b.norm()).then(a.im.total_cmp(&b.im)));
    poles
}

/// Index of each quantity in the plant state.
pub mod state {
    pub const CURRENT: usize = 0;
    pub const THETA_ROT: usize = 1;
    pub const W_ROT: usize = 2;
    pub const THETA_BS: usize = 3;
    pub const W_BS: usize = 4;
    pub const DELTA_SW: usize = 5;
    pub const W_SW: usize = 6;
}

/// What the control loop and the logger see of an actuator; the simulated plant implements it,
/// and so does the plant with unmodelled effects (`effect_plant.rs`).
pub trait Actuator {
    /// Advance one current-loop period with the terminal voltage held.
    fn step(&mut self, voltage_v: f64);
    /// Motor current, A (what the current sensor reads).
    fn current_a(&self) -> f64;
    /// Motor shaft angle, rad.
    fn motor_rad(&self) -> f64;
    /// Motor shaft speed, rad/s (the back-EMF of an open bridge).
    fn motor_speed_rad_s(&self) -> f64;
    /// Angle at the column encoder (pinion end, delta_P of section 3.2), rad.
    fn column_rad(&self) -> f64;
    /// Put the actuator at rest at a column angle: no current, no speed, nothing loaded.
    fn set_at_rest(&mut self, column_rad: f64);
}

/// The linear plant, discretised exactly for a fixed step.
#[derive(Debug, Clone)]
pub struct LinearPlant {
    params: PlantParams,
    ad: [[f64; 7]; 7],
    bd: [f64; 7],
    x: [f64; 7],
    dt_s: f64,
}

/// Why a plant could not be built.
#[derive(Debug, Clone, PartialEq)]
pub enum PlantError {
    /// A parameter is NaN, infinite, or not positive where it must be.
    BadParameter {
        name: &'static str,
        value: f64,
    },
    BadStep {
        dt_s: f64,
    },
}

impl std::fmt::Display for PlantError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PlantError::BadParameter { name, value } => {
                write!(f, "plant parameter {name} = {value} is not a valid value")
            }
            PlantError::BadStep { dt_s } => write!(f, "plant step {dt_s} s must be > 0"),
        }
    }
}

impl std::error::Error for PlantError {}

impl PlantParams {
    /// Refuse parameters or a step no plant can be built from: every parameter finite,
    /// positive where it divides, non-negative elsewhere, and a positive step.
    pub fn check(&self, dt_s: f64) -> Result<(), PlantError> {
        let params = self;
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return Err(PlantError::BadStep { dt_s });
        }
        let positive = [
            ("ra", params.ra),
            ("la", params.la),
            ("kt", params.kt),
            ("j_rot", params.j_rot),
            ("belt_reduction", params.belt_reduction),
            ("tau_bs", params.tau_bs),
            ("tau_p", params.tau_p),
            ("j_sw", params.j_sw),
        ];
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(PlantError::BadParameter { name, value });
            }
        }
        let non_negative = [
            ("ke", params.ke),
            ("r", params.r),
            ("m_bs", params.m_bs),
            ("m_r", params.m_r),
            ("tau_r", params.tau_r),
            ("j_bs", params.j_bs),
            ("j_w", params.j_w),
            ("k_b", params.k_b),
            ("beta_b", params.beta_b),
            ("beta_bs", params.beta_bs),
            ("k_tb", params.k_tb),
            ("beta_tb", params.beta_tb),
            ("beta_sw", params.beta_sw),
        ];
        for (name, value) in non_negative {
            if !(value.is_finite() && value >= 0.0) {
                return Err(PlantError::BadParameter { name, value });
            }
        }
        if params.j_bs_equivalent() <= 0.0 {
            return Err(PlantError::BadParameter {
                name: "j_bs_equivalent",
                value: params.j_bs_equivalent(),
            });
        }
        Ok(())
    }
}

impl LinearPlant {
    pub fn new(params: PlantParams, dt_s: f64) -> Result<Self, PlantError> {
        params.check(dt_s)?;
        let (a, b) = params.electromechanical_state_space();
        // ZOH: exp([[A, B], [0, 0]] dt) = [[Ad, Bd], [0, 1]]
        let mut aug = SMatrix::<f64, 8, 8>::zeros();
        aug.fixed_view_mut::<7, 7>(0, 0).copy_from(&(a * dt_s));
        aug.fixed_view_mut::<7, 1>(0, 7).copy_from(&(b * dt_s));
        let e = aug.exp();
        let mut ad = [[0.0; 7]; 7];
        let mut bd = [0.0; 7];
        for (i, row) in ad.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = e[(i, j)];
            }
            bd[i] = e[(i, 7)];
        }
        Ok(LinearPlant {
            params,
            ad,
            bd,
            x: [0.0; 7],
            dt_s,
        })
    }

    pub fn params(&self) -> &PlantParams {
        &self.params
    }

    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    pub fn state(&self) -> [f64; 7] {
        self.x
    }
}

/// `acc + Ad x` of a discretised step, column by column: the seven rows are seven independent
/// sums the CPU runs side by side (row by row, each waits on its previous add), each summed in
/// the same order as a row-by-row loop, so the result is the same to the bit. Half of a
/// diagnosis's time is here (`perf record` on `gap bench`).
pub(crate) fn add_ad_x(mut acc: [f64; 7], ad: &[[f64; 7]; 7], x: &[f64; 7]) -> [f64; 7] {
    for (j, xj) in x.iter().enumerate() {
        for (a, row) in acc.iter_mut().zip(ad.iter()) {
            *a += row[j] * xj;
        }
    }
    acc
}

impl Actuator for LinearPlant {
    fn set_at_rest(&mut self, column_rad: f64) {
        self.x = self.params.at_rest(column_rad);
    }

    fn step(&mut self, voltage_v: f64) {
        let mut next = [0.0; 7];
        for (acc, b) in next.iter_mut().zip(self.bd.iter()) {
            *acc = b * voltage_v;
        }
        self.x = add_ad_x(next, &self.ad, &self.x);
    }

    fn current_a(&self) -> f64 {
        self.x[state::CURRENT]
    }

    fn motor_rad(&self) -> f64 {
        self.x[state::THETA_ROT]
    }

    fn motor_speed_rad_s(&self) -> f64 {
        self.x[state::W_ROT]
    }

    fn column_rad(&self) -> f64 {
        self.x[state::THETA_BS] * self.params.screw_to_pinion()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poles_match_the_paper() {
        // Section 4.3: one pole at the origin, a real one at 334 rad/s, complex pairs at
        // 30.9 rad/s and 131 rad/s. Within 10 %.
        let poles = PlantParams::PAPER.mechanical_poles();
        assert_eq!(poles.len(), 6);
        assert!(poles[0].norm() < 1e-6, "origin pole {:?}", poles[0]);
        let pairs: Vec<_> = poles.iter().filter(|p| p.im > 1e-6).collect();
        assert_eq!(pairs.len(), 2, "two complex pairs in {poles:?}");
        let real: Vec<_> = poles
            .iter()
            .filter(|p| p.im.abs() <= 1e-6 && p.norm() > 1e-6)
            .collect();
        assert_eq!(real.len(), 1, "one real non-zero pole in {poles:?}");
        let within = |got: f64, want: f64| (got - want).abs() / want < 0.10;
        assert!(
            real[0].re < 0.0 && within(real[0].norm(), 334.0),
            "{:?}",
            real[0]
        );
        assert!(within(pairs[0].norm(), 30.9), "{:?}", pairs[0]);
        assert!(within(pairs[1].norm(), 131.0), "{:?}", pairs[1]);
        assert!(poles.iter().all(|p| p.re <= 1e-9), "stable or marginal");
    }

    #[test]
    fn equations_as_printed_miss_the_paper_poles() {
        // The check that found the printing errors: with tauB = 2 and (tauP/tauBS)^2 in
        // eq. 6 no pole lands near 30.9 rad/s. Emulated here through the belt factor alone.
        let mut p = PlantParams::PAPER;
        p.belt_reduction = 0.5; // eqs. 5-6 as printed use tauB = 2 where 1/2 belongs
        let poles = p.mechanical_poles();
        assert!(
            poles
                .iter()
                .all(|q| q.im.abs() < 1e-6 || (q.norm() - 30.9).abs() / 30.9 > 0.10),
            "{poles:?}"
        );
    }

    #[test]
    fn equivalent_screw_inertia_follows_eq_8() {
        let j = PlantParams::PAPER.j_bs_equivalent();
        assert!((j - 1.0757e-4).abs() < 1e-8, "{j}");
    }

    #[test]
    fn exact_discretisation_matches_fine_rk4() {
        let params = PlantParams::PAPER;
        let dt = 5e-5;
        let mut plant = LinearPlant::new(params, dt).unwrap();
        let (a, b) = params.electromechanical_state_space();
        let mut x = SVector::<f64, 7>::zeros();
        let sub = 50;
        let h = dt / sub as f64;
        let f = |x: &SVector<f64, 7>, v: f64| a * x + b * v;
        for k in 0..2000 {
            let v = if k < 1000 { 6.0 } else { -3.0 };
            plant.step(v);
            for _ in 0..sub {
                let k1 = f(&x, v);
                let k2 = f(&(x + k1 * (h / 2.0)), v);
                let k3 = f(&(x + k2 * (h / 2.0)), v);
                let k4 = f(&(x + k3 * h), v);
                x += (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6.0);
            }
        }
        for i in 0..7 {
            let scale = x[i].abs().max(1e-3);
            assert!(
                (plant.state()[i] - x[i]).abs() / scale < 1e-6,
                "state {i}: {} vs {}",
                plant.state()[i],
                x[i]
            );
        }
    }

    #[test]
    fn steady_voltage_gives_the_no_load_speed() {
        // With the load attached, w = v ke / (ke kt + Ra r_total): near the 24 V / ke = 457 rad/s
        // no-load figure of plant-and-control.md, a bit lower because of the damping.
        let mut plant = LinearPlant::new(PlantParams::PAPER, 5e-5).unwrap();
        for _ in 0..200_000 {
            plant.step(24.0);
        }
        let w = plant.state()[state::W_ROT];
        assert!(w > 300.0 && w < 457.2, "speed {w} rad/s");
    }

    #[test]
    fn refuses_bad_parameters() {
        let mut p = PlantParams::PAPER;
        p.la = 0.0;
        assert!(matches!(
            LinearPlant::new(p, 5e-5),
            Err(PlantError::BadParameter { name: "la", .. })
        ));
        let mut p = PlantParams::PAPER;
        p.k_b = f64::NAN;
        assert!(LinearPlant::new(p, 5e-5).is_err());
        assert!(LinearPlant::new(PlantParams::PAPER, 0.0).is_err());
    }

    #[test]
    fn at_rest_the_rigid_gear_ratio_holds() {
        let mut plant = LinearPlant::new(PlantParams::PAPER, 5e-5).unwrap();
        plant.set_at_rest(0.2);
        assert!((plant.column_rad() - 0.2).abs() < 1e-12);
        let ratio = plant.motor_rad() / plant.column_rad();
        assert!((ratio - PlantParams::PAPER.motor_per_pinion()).abs() < 1e-9);
        // and it stays there
        for _ in 0..1000 {
            plant.step(0.0);
        }
        assert!((plant.column_rad() - 0.2).abs() < 1e-9);
    }
}
