//! The catalogue of candidate effects: each one's parameters, bounds, minimum size and how
//! it enters the model.

use super::fit::ParamSpec;
use super::model::Effects;
use super::rig::{Rig, RigModel};

/// The candidate effects the diagnosis fits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum EffectKind {
    Backlash,
    CoulombFriction,
    Delay,
    TireGround,
    SupplySag,
    /// Coulomb friction at the rack (the `coulomb_friction` family's second place): acting
    /// through the soft belt it makes output hysteresis that friction at the motor cannot.
    RackFriction,
    /// Play in the belt/nut (the `backlash` family's second place): the motor turns through
    /// the gap without pulling the nut, so the motor angle and the column part on every
    /// reversal, which play between the pinion and the encoder cannot do.
    BeltPlay,
    /// The tyre under Dahl's law (the `tire_ground` family's second form): the force
    /// approaches its largest value smoothly, where the elasto-plastic bristle has a corner.
    TireDahl,
    /// The measured current late against the angles (the `delay` family's second place): a
    /// delay of every signal alike is `Delay` (a log cannot tell it from a late reference).
    CurrentDelay,
}

impl EffectKind {
    /// The paper rig's candidates: the four core effects, friction at the rack, play in the
    /// belt/nut, the Dahl tyre and the current late against the angles.
    pub const PAPER: [EffectKind; 8] = [
        EffectKind::Backlash,
        EffectKind::BeltPlay,
        EffectKind::CoulombFriction,
        EffectKind::RackFriction,
        EffectKind::Delay,
        EffectKind::CurrentDelay,
        EffectKind::TireGround,
        EffectKind::TireDahl,
    ];

    /// The four the issue asks for, in the order they are reported.
    pub const CORE: [EffectKind; 4] = [
        EffectKind::Backlash,
        EffectKind::CoulombFriction,
        EffectKind::Delay,
        EffectKind::TireGround,
    ];

    pub fn name(self) -> &'static str {
        match self {
            EffectKind::Backlash => "backlash",
            EffectKind::CoulombFriction => "coulomb_friction",
            EffectKind::Delay => "delay",
            EffectKind::TireGround => "tire_ground",
            EffectKind::SupplySag => "supply_sag",
            EffectKind::RackFriction => "coulomb_friction_rack",
            EffectKind::BeltPlay => "backlash_belt",
            EffectKind::TireDahl => "tire_ground_dahl",
            EffectKind::CurrentDelay => "delay_current",
        }
    }

    /// The family the verdict reports the effect under (`verdict.effects`): where the effect
    /// sits is in the ranking's name.
    pub fn family(self) -> &'static str {
        match self {
            EffectKind::RackFriction => "coulomb_friction",
            EffectKind::BeltPlay => "backlash",
            EffectKind::TireDahl => "tire_ground",
            EffectKind::CurrentDelay => "delay",
            k => k.name(),
        }
    }

    pub fn from_name(name: &str) -> Option<EffectKind> {
        [
            EffectKind::Backlash,
            EffectKind::CoulombFriction,
            EffectKind::Delay,
            EffectKind::TireGround,
            EffectKind::SupplySag,
            EffectKind::RackFriction,
            EffectKind::BeltPlay,
            EffectKind::TireDahl,
            EffectKind::CurrentDelay,
        ]
        .into_iter()
        .find(|k| k.name() == name)
    }

    /// The effects that make sense on a rig.
    pub fn for_rig(rig: &Rig) -> Vec<EffectKind> {
        match rig.model {
            RigModel::Paper(_) => EffectKind::PAPER.to_vec(),
            RigModel::Emps(_) => vec![
                EffectKind::Backlash,
                EffectKind::CoulombFriction,
                EffectKind::Delay,
                EffectKind::TireGround,
            ],
            RigModel::Bam(_) => vec![
                EffectKind::Backlash,
                EffectKind::CoulombFriction,
                EffectKind::Delay,
            ],
        }
    }

    /// The fitted parameters, their bounds, start and difference step, in the rig's units.
    pub fn specs(self, rig: &Rig) -> Vec<ParamSpec> {
        let paper = matches!(rig.model, RigModel::Paper(_));
        let spec = |name, lo, hi, start, step| ParamSpec {
            name,
            lo,
            hi,
            start,
            step,
        };
        match (self, &rig.model) {
            (EffectKind::Backlash, RigModel::Paper(_)) => {
                vec![spec("width_deg", 0.0, 4.0, 0.0, 0.1)]
            }
            (EffectKind::Backlash, RigModel::Bam(_)) => {
                vec![spec("width_rad", 0.0, 0.1, 0.0, 1e-3)]
            }
            (EffectKind::Backlash, _) => vec![spec("width_m", 0.0, 2e-3, 0.0, 1e-5)],
            (EffectKind::CoulombFriction, RigModel::Paper(_)) => {
                vec![spec("torque_nm", 0.0, 0.5, 0.0, 0.01)]
            }
            (EffectKind::CoulombFriction, RigModel::Emps(m)) => vec![
                spec("force_n", 0.0, 100.0, 0.0, 0.5),
                spec("viscous_ns_per_m", 0.0, 2.0 * m.fv, m.fv, 2.0),
            ],
            // Up to 0.5 N m, under the stall torque at 7.4 V through BAM's M1 kt and R (0.71 N m).
            (EffectKind::CoulombFriction, RigModel::Bam(m)) => vec![
                spec("torque_nm", 0.0, 0.5, 0.0, 1e-3),
                spec(
                    "viscous_nm_s_per_rad",
                    0.0,
                    0.05,
                    m.viscous_nm_s_per_rad,
                    2e-4,
                ),
            ],
            // On an EPOS4 car the delay is the latch's latency beyond the nominal SYNC phase
            // (`model::simulate_epos4`): a log cannot tell a late frame from a SYNC grid that
            // sits later, so the figure is the delay to within that phase, under a period.
            (EffectKind::Delay, _) => vec![spec(
                "delay_ms",
                0.0,
                if paper { 100.0 } else { 50.0 },
                0.0,
                if paper { 2.0 } else { 0.5 },
            )],
            (EffectKind::TireGround | EffectKind::TireDahl, RigModel::Paper(_)) => vec![
                spec("force_n", 0.0, 3000.0, 0.0, 60.0),
                spec("stiffness_n_per_mm", 50.0, 2000.0, 600.0, 50.0),
            ],
            (EffectKind::TireGround, _) => vec![
                spec("force_n", 0.0, 200.0, 0.0, 1.0),
                spec("stiffness_n_per_mm", 1.0, 2000.0, 200.0, 10.0),
            ],
            (EffectKind::SupplySag, RigModel::Paper(m)) => {
                vec![spec("supply_v", 8.0, 30.0, m.supply_v, 0.3)]
            }
            (EffectKind::SupplySag, _) => vec![],
            // The creep speed: how fast the rack must move before the friction is all there
            // (the force is F tanh(v / v_creep)). Sharp (0) up to a few mm/s, against the
            // rack's 5-250 mm/s in a sweep: grease and seals make real rack friction build up
            // over a speed, and a sharp model then reads the creep as play or a larger force.
            (EffectKind::RackFriction, RigModel::Paper(_)) => vec![
                spec("force_n", 0.0, 2000.0, 0.0, 40.0),
                spec("creep_mm_s", 0.0, 5.0, 0.0, 0.25),
            ],
            (EffectKind::RackFriction, _) => vec![],
            (EffectKind::BeltPlay, RigModel::Paper(_)) => {
                vec![spec("width_deg", 0.0, 4.0, 0.0, 0.1)]
            }
            (EffectKind::BeltPlay | EffectKind::TireDahl, _) => vec![],
            // Up to ten 10 ms periods: a current older than that is no current to control by.
            (EffectKind::CurrentDelay, RigModel::Paper(_)) => {
                vec![spec("delay_ms", 0.0, 100.0, 0.0, 2.0)]
            }
            (EffectKind::CurrentDelay, _) => vec![],
        }
    }

    /// The smallest size worth naming, on the effect's first parameter, in the rig's units:
    /// below it the effect is within the sensors' resolution or the grid's, and a fit that
    /// lands there is fitting the noise or another effect's shadow.
    pub fn min_size(self, rig: &Rig) -> f64 {
        match (self, &rig.model) {
            // The 12-bit column encoder reads 0.088 deg a count: play under about three counts
            // is within its quantisation.
            (EffectKind::Backlash, RigModel::Paper(_)) => 0.3,
            // 0.03 Nm is 0.57 A through kt = 52.5 mNm/A (Table 1), a tenth of the current's
            // chatter inside a reference period.
            (EffectKind::CoulombFriction, RigModel::Paper(_)) => 0.03,
            // One 10 ms reference period. The ECU holds each 100 Hz reference for a period,
            // so a reference late by less than one is within the frame's own jitter, and a
            // logger's stamps may sit a few ms off the instants its samples were taken at,
            // which no fit can tell from a delay. A fit below a period is such a clock, or a
            // second effect's phase: 5.2 and 5.8 ms fits named beside rack friction and a
            // tyre on two independent logs with no delay at all, where every
            // real delay came back at 17 ms or more.
            // And never under what the log's own timing can explain (its stamps' jitter, a
            // reference convention fitted from the log): that is the logger's, not the car's.
            (EffectKind::Delay, RigModel::Paper(m)) => 10.0_f64.max(1e3 * m.timing_bound_s),
            // 150 N at the rack is 0.024 Nm at the motor through tau_bs and the belt (Table
            // 2): the friction minimum's size.
            (EffectKind::TireGround | EffectKind::TireDahl, RigModel::Paper(_)) => 150.0,
            (EffectKind::SupplySag, _) => 0.0,
            // 200 N at the rack is 0.03 Nm at the motor through tau_bs and the belt (Table
            // 2), the motor friction's minimum.
            (EffectKind::RackFriction, _) => 200.0,
            // As the column play: 0.3 deg at the wheel is 26 deg of motor, 6 Hall counts, so
            // the motor sees it plainly; the column encoder's three counts are the limit.
            (EffectKind::BeltPlay, _) => 0.3,
            (EffectKind::Backlash, RigModel::Emps(_)) => 2e-5,
            (EffectKind::CoulombFriction, RigModel::Emps(_)) => 2.0,
            (EffectKind::Delay, RigModel::Emps(m)) => 0.2e3 * m.ts_s,
            (EffectKind::TireGround | EffectKind::TireDahl, RigModel::Emps(_)) => 2.0,
            // Three counts of the 4096-count encoder.
            (EffectKind::Backlash, RigModel::Bam(_)) => 3.0 * std::f64::consts::TAU / 4096.0,
            // Three counts of the 885-count PWM at the 7.4 V supply through kt / R (BAM's M1).
            (EffectKind::CoulombFriction, RigModel::Bam(m)) => {
                3.0 / m.pwm_full_scale * 7.4 * m.kt / m.r_ohm
            }
            // One step of the grid the log is resampled onto.
            (EffectKind::Delay, RigModel::Bam(m)) => 1e3 * m.ts_s,
            (EffectKind::TireGround | EffectKind::TireDahl, RigModel::Bam(_)) => f64::INFINITY,
            // Half a 10 ms period, within a logger's stamping. (A drive's current forwarded
            // one SYNC late is a whole period, so it stays above this.)
            (EffectKind::CurrentDelay, RigModel::Paper(_)) => 5.0,
            (EffectKind::CurrentDelay, _) => f64::INFINITY,
        }
    }

    /// Write fitted parameters into an effect set.
    pub fn apply(self, p: &[f64], fx: &mut Effects) {
        let get = |i: usize| p.get(i).copied().unwrap_or(0.0);
        match self {
            EffectKind::Backlash => fx.backlash = get(0),
            EffectKind::CoulombFriction => {
                fx.coulomb = get(0);
                if p.len() > 1 {
                    fx.viscous_override = get(1);
                }
            }
            EffectKind::Delay => fx.delay_s = get(0) * 1e-3,
            EffectKind::CurrentDelay => fx.effort_delay_s = get(0) * 1e-3,
            EffectKind::TireGround => {
                fx.tire_force_n = get(0);
                fx.tire_stiffness_n_per_mm = get(1);
            }
            EffectKind::SupplySag => fx.supply_v = get(0),
            EffectKind::RackFriction => {
                fx.rack_coulomb_n = get(0);
                fx.rack_creep_mm_s = get(1);
            }
            EffectKind::BeltPlay => fx.belt_play = get(0),
            EffectKind::TireDahl => {
                fx.tire_force_n = get(0);
                fx.tire_stiffness_n_per_mm = get(1);
                fx.tire_dahl = true;
            }
        }
    }
}

/// The fitted parameters of `kinds` in order, started at `start` where given, and how many
/// each effect has.
pub(super) fn specs_of(
    rig: &Rig,
    kinds: &[EffectKind],
    start: Option<&[f64]>,
) -> (Vec<ParamSpec>, Vec<usize>) {
    let mut specs: Vec<ParamSpec> = kinds.iter().flat_map(|k| k.specs(rig)).collect();
    if let Some(s) = start {
        for (sp, v) in specs.iter_mut().zip(s) {
            sp.start = *v;
        }
    }
    let lens = kinds.iter().map(|k| k.specs(rig).len()).collect();
    (specs, lens)
}

/// Where `kind`'s first parameter sits among the stacked parameters of `kinds` (as
/// [`specs_of`] stacks them); `None` if `kinds` does not hold it.
pub(super) fn first_param_at(rig: &Rig, kinds: &[EffectKind], kind: EffectKind) -> Option<usize> {
    let p = kinds.iter().position(|k| *k == kind)?;
    Some(kinds[..p].iter().map(|k| k.specs(rig).len()).sum())
}

/// Write the values `p` of `kinds` (each `lens` long, as [`specs_of`] counts) into `fx`.
pub(super) fn apply_all(kinds: &[EffectKind], lens: &[usize], p: &[f64], fx: &mut Effects) {
    let mut i = 0;
    for (k, n) in kinds.iter().zip(lens) {
        k.apply(&p[i..i + n], fx);
        i += n;
    }
}
