//! Controller gains as a user types them (the units of the paper's Table 3, which are the
//! EPOS4's current and position control parameter sets 0x30A0 / 0x30A1 scaled by 1000), and
//! the SI gains the loops run on, converted once here.
//!
//! A [`SiGains`] can only be made through [`EposGains::to_si`], which refuses NaN, infinity and
//! negative gains, so a loop never runs on a gain that is not a finite number >= 0.

/// Gains in the units of Table 3. The EPOS4 objects hold the same quantities in micro-units
/// (uV/A, uA/rad, ...), i.e. 1000 x these numbers; the CANopen layer does that scaling.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct EposGains {
    /// Current controller P gain, mV/A (0x30A0 sub 1).
    pub current_kp_mv_per_a: f32,
    /// Current controller I gain, mV/(A ms) (0x30A0 sub 2).
    pub current_ki_mv_per_a_ms: f32,
    /// Position controller P gain, mA/rad (0x30A1 sub 1).
    pub position_kp_ma_per_rad: f32,
    /// Position controller I gain, mA/(rad s) (0x30A1 sub 2).
    pub position_ki_ma_per_rad_s: f32,
    /// Position controller D gain, mA s/rad (0x30A1 sub 3).
    pub position_kd_ma_s_per_rad: f32,
    /// Velocity feedforward, mA s/rad (0x30A1 sub 4).
    pub ff_velocity_ma_s_per_rad: f32,
    /// Acceleration feedforward, mA s^2/rad (0x30A1 sub 5).
    pub ff_acceleration_ma_s2_per_rad: f32,
}

impl EposGains {
    /// The paper's gains, Table 3.
    pub const PAPER: EposGains = EposGains {
        current_kp_mv_per_a: 2000.0,
        current_ki_mv_per_a_ms: 2100.0,
        position_kp_ma_per_rad: 4390.0,
        position_ki_ma_per_rad_s: 7352.0,
        position_kd_ma_s_per_rad: 159.87,
        ff_velocity_ma_s_per_rad: 12.59,
        ff_acceleration_ma_s2_per_rad: 1.783,
    };

    /// Convert to SI, refusing the first gain that is NaN, infinite or negative.
    pub fn to_si(&self) -> Result<SiGains, GainError> {
        let checked = |value: f32, gain: Gain| -> Result<f32, GainError> {
            if !value.is_finite() {
                Err(GainError::NotFinite { gain })
            } else if value < 0.0 {
                Err(GainError::Negative { gain })
            } else {
                Ok(value)
            }
        };
        Ok(SiGains {
            // mV/A -> V/A
            current_kp: checked(self.current_kp_mv_per_a, Gain::CurrentKp)? * 1e-3,
            // mV/(A ms) -> V/(A s): x 1e-3 (mV -> V) x 1e3 (1/ms -> 1/s)
            current_ki: checked(self.current_ki_mv_per_a_ms, Gain::CurrentKi)?,
            // mA/... -> A/...
            position_kp: checked(self.position_kp_ma_per_rad, Gain::PositionKp)? * 1e-3,
            position_ki: checked(self.position_ki_ma_per_rad_s, Gain::PositionKi)? * 1e-3,
            position_kd: checked(self.position_kd_ma_s_per_rad, Gain::PositionKd)? * 1e-3,
            ff_velocity: checked(self.ff_velocity_ma_s_per_rad, Gain::FfVelocity)? * 1e-3,
            ff_acceleration: checked(self.ff_acceleration_ma_s2_per_rad, Gain::FfAcceleration)?
                * 1e-3,
        })
    }
}

/// Which gain a [`GainError`] is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Gain {
    CurrentKp,
    CurrentKi,
    PositionKp,
    PositionKi,
    PositionKd,
    FfVelocity,
    FfAcceleration,
}

/// Why a set of gains was refused; the loops keep their previous gains.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GainError {
    NotFinite { gain: Gain },
    Negative { gain: Gain },
}

impl core::fmt::Display for GainError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            GainError::NotFinite { gain } => write!(f, "gain {gain:?} is NaN or infinite"),
            GainError::Negative { gain } => write!(f, "gain {gain:?} is negative"),
        }
    }
}

/// Gains in SI units, valid by construction (finite, >= 0).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SiGains {
    /// V/A
    current_kp: f32,
    /// V/(A s)
    current_ki: f32,
    /// A/rad (motor)
    position_kp: f32,
    /// A/(rad s)
    position_ki: f32,
    /// A s/rad
    position_kd: f32,
    /// A s/rad
    ff_velocity: f32,
    /// A s^2/rad
    ff_acceleration: f32,
}

impl SiGains {
    /// All gains zero: no action at all. The safe fallback where valid gains are missing.
    pub const ZERO: SiGains = SiGains {
        current_kp: 0.0,
        current_ki: 0.0,
        position_kp: 0.0,
        position_ki: 0.0,
        position_kd: 0.0,
        ff_velocity: 0.0,
        ff_acceleration: 0.0,
    };

    /// These current-loop gains with other position-loop gains (A/rad, A/(rad s), A s/rad,
    /// A s/rad, A s^2/rad); `None` if any is negative or not finite.
    pub fn with_position_loop(
        &self,
        kp: f32,
        ki: f32,
        kd: f32,
        ff_velocity: f32,
        ff_acceleration: f32,
    ) -> Option<SiGains> {
        let all = [kp, ki, kd, ff_velocity, ff_acceleration];
        all.iter()
            .all(|g| g.is_finite() && *g >= 0.0)
            .then_some(SiGains {
                position_kp: kp,
                position_ki: ki,
                position_kd: kd,
                ff_velocity,
                ff_acceleration,
                ..*self
            })
    }

    pub fn current_kp(&self) -> f32 {
        self.current_kp
    }
    pub fn current_ki(&self) -> f32 {
        self.current_ki
    }
    pub fn position_kp(&self) -> f32 {
        self.position_kp
    }
    pub fn position_ki(&self) -> f32 {
        self.position_ki
    }
    pub fn position_kd(&self) -> f32 {
        self.position_kd
    }
    pub fn ff_velocity(&self) -> f32 {
        self.ff_velocity
    }
    pub fn ff_acceleration(&self) -> f32 {
        self.ff_acceleration
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_gains_convert_to_si() {
        let si = EposGains::PAPER.to_si().expect("Table 3 gains are valid");
        assert!((si.current_kp() - 2.0).abs() < 1e-6); // 2000 mV/A = 2 V/A
        assert!((si.current_ki() - 2100.0).abs() < 1e-3); // 2100 mV/(A ms) = 2100 V/(A s)
        assert!((si.position_kp() - 4.39).abs() < 1e-6);
        assert!((si.position_ki() - 7.352).abs() < 1e-6);
        assert!((si.position_kd() - 0.15987).abs() < 1e-7);
        assert!((si.ff_velocity() - 0.01259).abs() < 1e-8);
        assert!((si.ff_acceleration() - 0.001783).abs() < 1e-9);
    }

    #[test]
    fn current_pi_zero_cancels_the_winding_pole() {
        // plant-and-control.md: KI/KP = 1050 rad/s = Ra/La (Table 1: 0.293 ohm / 0.279 mH).
        let si = EposGains::PAPER.to_si().expect("valid");
        let zero = si.current_ki() / si.current_kp();
        assert!((zero - 0.293 / 0.279e-3).abs() < 1.0, "zero {zero} rad/s");
    }

    #[test]
    fn refuses_nan_infinite_and_negative_gains() {
        let mut g = EposGains::PAPER;
        g.position_kd_ma_s_per_rad = f32::NAN;
        assert_eq!(
            g.to_si(),
            Err(GainError::NotFinite {
                gain: Gain::PositionKd
            })
        );
        let mut g = EposGains::PAPER;
        g.current_ki_mv_per_a_ms = f32::INFINITY;
        assert_eq!(
            g.to_si(),
            Err(GainError::NotFinite {
                gain: Gain::CurrentKi
            })
        );
        let mut g = EposGains::PAPER;
        g.ff_velocity_ma_s_per_rad = -1.0;
        assert_eq!(
            g.to_si(),
            Err(GainError::Negative {
                gain: Gain::FfVelocity
            })
        );
    }

    #[test]
    fn zero_gains_are_allowed() {
        let mut g = EposGains::PAPER;
        g.position_ki_ma_per_rad_s = 0.0;
        assert!(g.to_si().is_ok());
    }
}
