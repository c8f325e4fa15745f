//! Direct drive: the three Hall sensors of the BLDC motor and six-step (block) commutation of
//! a three-phase bridge, for when the ECU runs the cascade itself instead of an EPOS4.
//!
//! Hall code (bits H3 H2 H1) -> electrical sector 0..5, with the usual 120-degree sensor
//! placement:
//!
//! ```text
//!  sector   0    1    2    3    4    5
//!  H3H2H1  001  011  010  110  100  101
//!  drive   A+B- A+C- B+C- B+A- C+A- C+B-   (positive torque; negative swaps + and -)
//! ```
//!
//! Codes 000 and 111 cannot occur with healthy sensors: a broken wire or a dead sensor. They
//! and a jump of more than one sector between two samples (the motor cannot turn 120 electrical
//! degrees in one 50 us sample below 28 000 rpm) are faults: the bridge is switched off.
//! Which phase leads which winding is a property of the motor's wiring; if the motor turns the
//! wrong way, swap two phase wires or the `phase_offset` in [`HallDecoder::new`].

/// One half-bridge of the three-phase bridge.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Leg {
    /// High side PWM at this duty (0..=1), low side complementary (with dead time in hardware).
    Pwm(f32),
    /// Low side on: the phase is tied to the negative rail.
    Low,
    /// Both switches off: the phase floats.
    Off,
}

/// The state of the three legs A, B, C.
pub type BridgeCommand = [Leg; 3];

/// Everything off: what the bridge does on any fault.
pub const BRIDGE_OFF: BridgeCommand = [Leg::Off, Leg::Off, Leg::Off];

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum HallError {
    /// 000 or 111: a sensor or its wiring is broken.
    InvalidCode { code: u8 },
    /// Two or three sectors between consecutive samples: a missed edge or noise.
    Jump { from: u8, to: u8 },
}

/// Sector of a Hall code, `None` for the two impossible codes. Bits above the three used are
/// ignored.
pub const fn sector_of(code: u8) -> Option<u8> {
    match code & 0b111 {
        0b001 => Some(0),
        0b011 => Some(1),
        0b010 => Some(2),
        0b110 => Some(3),
        0b100 => Some(4),
        0b101 => Some(5),
        _ => None,
    }
}

/// (high leg, low leg) for positive torque per sector (the table in the module docs).
const POSITIVE_TORQUE: [(usize, usize); 6] = [(0, 1), (0, 2), (1, 2), (1, 0), (2, 0), (2, 1)];

/// The Hall code of a sector (the inverse of [`sector_of`]), taken modulo 6.
pub const fn code_of(sector: u8) -> u8 {
    match sector % 6 {
        0 => 0b001,
        1 => 0b011,
        2 => 0b010,
        3 => 0b110,
        4 => 0b100,
        _ => 0b101,
    }
}

/// Tracks the multi-turn Hall count (6 per electrical revolution; 84 per motor revolution on
/// the EC 60 flat) from successive samples.
#[derive(Debug, Clone)]
pub struct HallDecoder {
    sector: Option<u8>,
    count: i32,
    phase_offset: u8,
}

impl HallDecoder {
    /// `phase_offset` (0..5, taken modulo 6) rotates the commutation table to match a motor's
    /// wiring.
    pub fn new(phase_offset: u8) -> Self {
        HallDecoder {
            sector: None,
            count: 0,
            phase_offset: phase_offset % 6,
        }
    }

    /// Multi-turn count: +1 per sector forward, -1 backward, saturating.
    pub fn count(&self) -> i32 {
        self.count
    }

    /// The last valid sector, if any.
    pub fn sector(&self) -> Option<u8> {
        self.sector
    }

    /// Take a sample. On an error the count and sector keep their last valid values and the
    /// caller switches the bridge off.
    pub fn update(&mut self, code: u8) -> Result<i32, HallError> {
        let now = sector_of(code).ok_or(HallError::InvalidCode { code: code & 0b111 })?;
        if let Some(before) = self.sector {
            // Both sectors are 0..=5, so nothing wraps: the forward distance modulo 6.
            let step = now.wrapping_add(6).wrapping_sub(before) % 6;
            match step {
                0 => {}
                1 => self.count = self.count.saturating_add(1),
                5 => self.count = self.count.saturating_sub(1),
                _ => {
                    return Err(HallError::Jump {
                        from: before,
                        to: now,
                    });
                }
            }
        }
        self.sector = Some(now);
        Ok(self.count)
    }

    /// The current of the winding pair the sector drives, from the three phase currents
    /// (positive into the motor): the current of the leg that positive torque drives high in
    /// this sector. Positive means positive torque whichever way the bridge drives it. `None`
    /// without a valid sector. A non-finite phase current passes through (the over-current
    /// check counts it).
    pub fn winding_current(&self, phases: [f32; 3]) -> Option<f32> {
        let (high, _) = self.driven_legs()?;
        phases.get(high).copied()
    }

    /// The (high, low) legs positive torque drives in the current sector; `None` without a
    /// valid sector.
    pub fn driven_legs(&self) -> Option<(usize, usize)> {
        let sector = self.sector?;
        // Both 0..=5 (`sector_of`, `new`): the sum does not wrap.
        POSITIVE_TORQUE
            .get(usize::from(sector.wrapping_add(self.phase_offset) % 6))
            .copied()
    }

    /// The terminal voltage a bridge command puts across the winding pair of the current
    /// sector: +duty x supply when it drives positive torque, -duty x supply when it drives
    /// negative torque, `None` when the bridge is off or the command does not match the sector
    /// (the inverse of [`HallDecoder::commutate`]; host-sim's bridge model uses it).
    pub fn terminal_voltage(&self, command: &BridgeCommand, supply: f32) -> Option<f32> {
        let (high, low) = self.driven_legs()?;
        match (command.get(high)?, command.get(low)?) {
            (Leg::Pwm(duty), Leg::Low) => Some(duty * supply),
            (Leg::Low, Leg::Pwm(duty)) => Some(-duty * supply),
            _ => None,
        }
    }

    /// Bridge legs for a terminal voltage at a supply voltage, six-step: the voltage's sign
    /// picks the direction, its magnitude the duty (clamped to 0..1). Without a valid sector,
    /// or with a non-finite or non-positive supply, the bridge is off.
    pub fn commutate(&self, voltage: f32, supply: f32) -> BridgeCommand {
        let Some((mut high, mut low)) = self.driven_legs() else {
            return BRIDGE_OFF;
        };
        if !(voltage.is_finite() && supply.is_finite() && supply > 0.0) {
            return BRIDGE_OFF;
        }
        let duty = (voltage.abs() / supply).clamp(0.0, 1.0);
        if voltage < 0.0 {
            core::mem::swap(&mut high, &mut low);
        }
        let mut legs = BRIDGE_OFF;
        // The table holds leg numbers 0..=2; a leg outside would leave it off.
        if let Some(leg) = legs.get_mut(high) {
            *leg = Leg::Pwm(duty);
        }
        if let Some(leg) = legs.get_mut(low) {
            *leg = Leg::Low;
        }
        legs
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FORWARD: [u8; 6] = [0b001, 0b011, 0b010, 0b110, 0b100, 0b101];

    #[test]
    fn one_electrical_turn_counts_six_each_way() {
        let mut d = HallDecoder::new(0);
        for code in FORWARD.iter().cycle().take(13) {
            d.update(*code).unwrap();
        }
        assert_eq!(
            d.count(),
            12,
            "first sample sets the sector, 12 steps after it"
        );
        for code in FORWARD.iter().rev().cycle().skip(5).take(13) {
            d.update(*code).unwrap();
        }
        assert_eq!(d.count(), 0);
    }

    #[test]
    fn impossible_codes_and_jumps_are_faults_and_switch_the_bridge_off_for_the_caller() {
        let mut d = HallDecoder::new(0);
        assert_eq!(d.update(0b000), Err(HallError::InvalidCode { code: 0 }));
        assert_eq!(d.update(0b111), Err(HallError::InvalidCode { code: 7 }));
        assert_eq!(d.commutate(12.0, 24.0), BRIDGE_OFF, "no valid sector yet");
        d.update(0b001).unwrap();
        assert_eq!(d.update(0b010), Err(HallError::Jump { from: 0, to: 2 }));
        assert_eq!(d.count(), 0);
        assert_eq!(d.sector(), Some(0), "keeps the last valid sector");
    }

    #[test]
    fn commutation_drives_two_legs_and_floats_the_third() {
        let mut d = HallDecoder::new(0);
        d.update(0b001).unwrap();
        assert_eq!(d.commutate(12.0, 24.0), [Leg::Pwm(0.5), Leg::Low, Leg::Off]);
        assert_eq!(
            d.commutate(-12.0, 24.0),
            [Leg::Low, Leg::Pwm(0.5), Leg::Off]
        );
        assert_eq!(d.commutate(48.0, 24.0), [Leg::Pwm(1.0), Leg::Low, Leg::Off]);
        for (i, code) in FORWARD.iter().enumerate() {
            let mut d = HallDecoder::new(0);
            d.update(*code).unwrap();
            let legs = d.commutate(6.0, 24.0);
            let off = legs.iter().filter(|l| **l == Leg::Off).count();
            assert_eq!(off, 1, "sector {i}: one floating leg in {legs:?}");
        }
    }

    #[test]
    fn winding_current_and_terminal_voltage_invert_commutation_in_every_sector() {
        for offset in 0..6u8 {
            for sector in 0..6u8 {
                let mut d = HallDecoder::new(offset);
                assert_eq!(sector_of(code_of(sector)), Some(sector));
                d.update(code_of(sector)).unwrap();
                for v in [-18.0f32, -3.0, 0.5, 12.0] {
                    let cmd = d.commutate(v, 24.0);
                    let back = d.terminal_voltage(&cmd, 24.0).unwrap();
                    assert!((back - v).abs() < 1e-5, "sector {sector}: {v} -> {back}");
                }
                // 5 A of positive torque: into the high leg, out of the low leg.
                let (high, low) = POSITIVE_TORQUE[((sector + offset) % 6) as usize];
                let mut phases = [0.0; 3];
                phases[high] = 5.0;
                phases[low] = -5.0;
                assert_eq!(d.winding_current(phases), Some(5.0));
            }
        }
        let d = HallDecoder::new(0);
        assert_eq!(d.winding_current([1.0, -1.0, 0.0]), None, "no sector yet");
        assert_eq!(d.terminal_voltage(&BRIDGE_OFF, 24.0), None);
    }

    #[test]
    fn garbage_never_panics_and_never_drives_on_bad_supply() {
        let mut d = HallDecoder::new(200);
        for code in 0..=255u8 {
            let _ = d.update(code);
            for (v, s) in [(f32::NAN, 24.0), (1.0, f32::NAN), (1.0, 0.0), (1.0, -24.0)] {
                assert_eq!(d.commutate(v, s), BRIDGE_OFF);
            }
            for leg in d.commutate(f32::MAX, 24.0) {
                if let Leg::Pwm(duty) = leg {
                    assert!((0.0..=1.0).contains(&duty));
                }
            }
        }
    }
}
