//! What the diagnosis answers ([`Diagnosis`], [`Verdict`], each [`Candidate`]), how it is
//! run ([`Options`]) and the readable report.

use super::effects::{apply_all, specs_of};
use super::fit::FitOptions;
use super::model::Effects;
use super::rig::Rig;
use super::score::{Offset, Scale};
use super::{EffectKind, Fit, Noise, identify, locate};
use std::collections::BTreeMap;

/// One candidate (or pair) after its fit.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct Candidate {
    /// Effect name; a pair is `a+b`.
    pub effect: String,
    pub params: BTreeMap<String, f64>,
    /// Standard error of each parameter.
    pub std_err: BTreeMap<String, f64>,
    pub gof: f64,
    pub gof_validation: Option<f64>,
    pub fit: Fit,
    pub fit_validation: Option<Fit>,
    /// Share of the nominal model's cost this effect removes.
    pub improvement: f64,
    /// Every parameter at least two standard errors from zero.
    pub significant: bool,
    /// Every effect at least its minimum physical size ([`EffectKind::min_size`]).
    pub large_enough: bool,
    pub simulations: usize,
    #[serde(skip)]
    pub kinds: Vec<EffectKind>,
    #[serde(skip)]
    pub values: Vec<f64>,
    #[serde(skip)]
    pub cost: f64,
}

/// What kind of answer the diagnosis gives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum VerdictKind {
    /// The nominal model leaves no more than the noise.
    None,
    /// One or two named effects, each above its minimum size, remove the gap.
    Effects,
    /// A refit of Table 4's nine parameters (`identify`) explains the log better than any
    /// effect.
    Parameters,
    /// Far above the noise, and no candidate removes enough of it.
    Unexplained,
}

/// The verdict: the effects named, and the GoF with them.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Verdict {
    pub kind: VerdictKind,
    /// The named effects; `["unexplained"]` for that kind, empty for none.
    pub effects: Vec<String>,
    pub gof_after: f64,
    pub gof_validation: Option<f64>,
    pub fit_after: Fit,
    pub fit_validation: Option<Fit>,
    /// Why: the cost left, the noise floor, and the rule that applied.
    pub reason: String,
    /// The candidate (or pair) the verdict names, with the sizes it was fitted at (`effects`
    /// names their families); `None` unless effects are named.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fitted: Option<Candidate>,
}

/// Two readings of a size agree within this share of the larger: a fit and the torque
/// balance further apart leave the size uncertain by as much.
pub const SIZES_AGREE_WITHIN: f64 = 0.2;

/// What a named `delay_current` means for the car, on the verdict's lines: the angles follow
/// the reference on time and the current lags them, so the reference does not reach the car
/// late; the current is reported late.
pub const CURRENT_LATE: &str = "the current lags the angles, which follow the reference on \
     time: the current is reported late (a logger's low-pass filter, a drive's averaged \
     current, or one a SYNC old), not the reference reaching the car late";

/// The play a verdict names beside the torque balance's reading of it (`balance` and its
/// standard error, deg), as one line of the report that says whether the two agree within
/// [`SIZES_AGREE_WITHIN`].
pub fn play_beside_balance(
    fitted_deg: f64,
    balance_deg: f64,
    balance_se_deg: f64,
    against_model: bool,
) -> String {
    let larger = fitted_deg.abs().max(balance_deg.abs()).max(1e-12);
    let apart = (fitted_deg - balance_deg).abs() / larger;
    format!(
        "size of the play: {fitted_deg:.2} deg as fitted; the torque balance ({}) reads \
         {balance_deg:.2} +- {balance_se_deg:.2} deg in the belt: {}",
        if against_model {
            "no fit: the log's less the nominal model's"
        } else {
            "no fit: the log alone"
        },
        if apart <= SIZES_AGREE_WITHIN {
            format!("the two agree within {:.0} %", 100.0 * SIZES_AGREE_WITHIN)
        } else {
            format!(
                "the two differ by {:.0} % of the larger, and the play's size is as uncertain",
                100.0 * apart
            )
        }
    )
}

/// Everything the diagnosis found.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Diagnosis {
    pub rig: String,
    pub duration_s: f64,
    pub baseline_gof: f64,
    pub baseline: Fit,
    pub baseline_validation: Option<Fit>,
    /// Normalised cost of the nominal model, and the floor the noise alone leaves.
    pub baseline_cost: f64,
    pub noise_floor_cost: f64,
    /// Each signal's noise (its unit), estimated from the nominal residual; the likelihood
    /// divides each residual by it.
    pub noise: Option<Noise>,
    /// The nominal model against itself with the reference moved by a ten-millionth of its
    /// range ([`super::repeatability`]): how closely any model can predict this log. A loop that
    /// feeds a quantised signal back (the ECU's column terms on the AMT20's counts, the direct
    /// drive's Hall edges) changes the phase of its chatter on any disturbance, so its own
    /// GoF falls below 100 % by what no model can follow sample for sample.
    pub repeatability: Fit,
    /// The constant part of the nominal model's effort residual (`score::effort_offset`).
    pub effort_offset: Offset,
    /// The constant part of the nominal model's output residual (`score::output_offset`).
    pub output_offset: Offset,
    /// How many times the nominal model's effort the log's is (`score::effort_scale`).
    pub effort_scale: Scale,
    /// The same with a Coulomb friction's current fitted beside it
    /// (`score::effort_scale_beside_friction`): what scales, not what the motion's sign adds.
    pub effort_scale_beside_friction: Scale,
    /// The strongest line the effort residual keeps against the motor's angle
    /// (`ripple::motor_ripple`), on the paper rig with a motor column.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motor_ripple: Option<super::ripple::MotorRipple>,
    /// What the log says of play in the belt and Coulomb friction at the rack, by itself or
    /// against the nominal model's own balance on an EPOS4 car
    /// (`gap::signature`), on the paper rig with a motor column; the candidates it rules out
    /// are named in the verdict's reason.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub signature: Option<super::signature::Signature>,
    pub verdict: Verdict,
    pub ranking: Vec<Candidate>,
    #[serde(rename = "where")]
    pub where_: locate::Where,
    /// Parameters of Table 4 the nominal model started from after `--refit-linear`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refit_linear: Option<identify::Identified>,
    /// The Table 4 refit tried for the `parameters` verdict (when the nominal model was well
    /// above its noise).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parameters: Option<identify::Identified>,
    pub simulations: usize,
    pub elapsed_s: f64,
    /// An EPOS4 car whose drive clock this diagnosis fitted again with its best single
    /// candidate in the model, and moved: every figure is on the moved clock
    /// ([`super::drive_clock::with_best`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub clock_refit: Option<super::drive_clock::ClockRefit>,
}

/// The rules a verdict is made by. Each is a property of the diagnosis, not a knob: the
/// selftests measure them together, so one changed alone is a different diagnosis.
///
/// An effect is named when it removes at least this share of the reducible cost (nominal
/// cost minus the noise floor): less, and a candidate is soaking up noise or a model a few
/// per cent off Table 4...
pub const MIN_SHARE_OF_REDUCIBLE: f64 = 0.3;
/// ...and at least this share of the whole nominal cost.
pub const MIN_IMPROVEMENT: f64 = 0.15;
/// A second effect is added when the pair removes this share of what the first left...
pub const MIN_PAIR_IMPROVEMENT: f64 = 0.2;
/// ...and this share of the noise floor: a pair always fits a little more than one effect.
pub const MIN_PAIR_SHARE_OF_FLOOR: f64 = 0.1;
/// With nothing named, a nominal cost above this many times the noise floor is
/// `unexplained` rather than `none`: a residual RMS over twice the noise's. Below it a
/// model a few per cent off Table 4 (no car matches the table) is no finding.
pub const UNEXPLAINED_RATIO: f64 = 5.0;
/// ...and only when the nominal GoF (eq. 11, combined) is below this: a noiseless log
/// puts any model far above its floor, but a model that leaves under a tenth of the
/// signals is no gap worth a verdict.
pub const UNEXPLAINED_BELOW_GOF: f64 = 0.9;
/// LM iterations of each Table 4 refit (`parameters`): each costs a simulation per parameter
/// and two more, and a log may be refitted from several starts.
/// A constant in the effort's residual (`score::effort_offset`) is no noise when its
/// intercept stands this many standard errors from zero... (effect-free cars of either drive
/// and controller, sweeps and tracks: at most 0.7; a 0.3 A offset added to their current: 21
/// or more)
pub const OFFSET_SIGNIFICANCE: f64 = 6.0;
/// ...and is at least this share of the logged effort's RMS: a gap worth a team's look, not a
/// rounding of the drive's current (effect-free cars: at most 0.1 %; a 0.3 A offset: 2.4-3.4 %
/// of sweeps of 9-12 A RMS).
pub const OFFSET_MIN_SHARE: f64 = 0.01;
/// The output's offset (`score::output_offset`) stands out beyond this share of the logged
/// output's RMS: a track's column (about 28 deg RMS) then needs 0.07 deg, under one count of
/// the column encoder (0.088 deg), so a zero a few counts off is read on a track as on a sweep.
/// The significance is what keeps cars without one out: the independent world's cars (the
/// first 60, effect-free or not; the EPOS4 car's first 40 under four loggers) and the
/// simulated car's eight logs at most 2.0 standard errors; zeros of 3-11 counts 10.9 or more.
pub const OUTPUT_OFFSET_MIN_SHARE: f64 = 0.0025;
/// ...and beyond this many counts of the position sensor (the column encoder's on the paper
/// rig, 0.088 deg): a car at rest reads the count it stands in, and the model starts at that
/// count, so about a count is where the car stood, not a zero (the simulated cars started
/// 0.03-0.08 deg above a count read 0.028-0.098 deg throughout their sweeps, up to 1.1 counts
/// under the ECU controller, 0.3-0.9 standard errors of scatter beside it); half a count more
/// for that. The world's zeros, 3-11 counts, read within 0.3 counts of what they are.
pub const OUTPUT_OFFSET_MIN_COUNTS: f64 = 1.5;
/// With nothing named, a log whose effort is more than this share off the nominal model's
/// throughout (`score::effort_scale`, or `score::effort_scale_beside_friction`, by
/// [`OFFSET_SIGNIFICANCE`] standard errors or more) is not the nominal car: a torque constant
/// or a current scale off. Effect-free cars of the independent world (Table 4 off by up to
/// 10 %, either drive, every logger): at most 7.2 % off alone, 8 % beside; the simulated car:
/// 1.2 %; the world's cars with the torque constant x0.7-0.8 or x1.25-1.4: 22-37 % alone
/// (a x0.80 read 14 % alone under a team's logger, and 17 % beside).
pub const SCALE_MIN_SHARE: f64 = 0.15;
/// A friction is not named where the log's current stands a share above the model's
/// (`SCALE_MIN_SHARE`) at this many standard errors or more (and keeps
/// [`SCALE_LEFT_BESIDE_FRICTION`] of it beside the motion's sign): a rack friction's share of
/// the slope changes with the band a sweep is in and from one part of a track to the next (it
/// rides on the damping's current, which goes with the motion's sign), a torque constant's does
/// not, and a longer log does not raise it. The independent world's cars named friction,
/// sweeps and 120 s tracks, either drive and every logger (the 200, the EPOS4 car's 40 under
/// its four loggers, the first 60 under the drawn ones), read at most 6.0 standard errors
/// (x1.07-1.43); its torque constants x0.71-0.74 that friction fitted alone stood in for,
/// 42-93.
pub const FRICTION_FOR_SCALE_SIGNIFICANCE: f64 = 12.0;
/// ...and where at least this share of that share is left with a friction of the motion's sign
/// fitted beside it (`score::effort_scale_beside_friction`): a friction at the motor is the
/// motion's sign, and keeps a steady share (0.15 Nm on the model's own car: x1.62 at 17
/// standard errors) of which a ninth is left beside the sign (x1.07); the world's torque
/// constants x0.7-0.8 read at 12 standard errors or more keep 0.36-1.14 of theirs.
pub const SCALE_LEFT_BESIDE_FRICTION: f64 = 0.25;
pub const PARAMETER_ITERATIONS: usize = 6;
/// The refit is the verdict when its cost is below this share of the best effect
/// verdict's (or of the nominal cost), besides removing what an effect must remove...
pub const PARAMETERS_COST_SHARE: f64 = 0.6;
/// ...and some parameter moved more than this factor from Table 4: within it, the car
/// is the table's within its tolerance (the paper's parameters are identified, not measured).
pub const PARAMETER_TOLERANCE: f64 = 1.5;
/// Logs longer than this are fitted on their worst window of this length, s: the fits then
/// cost the same for any log length, and 30 s hold several reversals of any sweep or track.
pub const MAX_FIT_S: f64 = 30.0;

/// How to run a diagnosis.
#[derive(Debug, Clone)]
pub struct Options {
    pub effects: Vec<EffectKind>,
    pub fit: FitOptions,
    pub threads: usize,
    pub progress: bool,
    /// Use the log's own torque balance (`gap::signature`) where it holds: on by default. Off,
    /// the diagnosis runs as it does where the balance does not hold, which is how the tests
    /// of the other rules see those rules at work.
    pub torque_balance: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            effects: EffectKind::CORE.to_vec(),
            fit: FitOptions::default(),
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
            progress: false,
            torque_balance: true,
        }
    }
}

impl Candidate {
    /// The play it names, deg at the column, with its candidate's name (`backlash` between
    /// the pinion and the encoder, `backlash_belt` in the belt/nut).
    pub fn play_deg(&self) -> Option<(&'static str, f64)> {
        let play = *self
            .kinds
            .iter()
            .find(|k| k.family() == EffectKind::Backlash.family())?;
        let key = super::search::param_key(&self.kinds, play, "width_deg");
        self.params.get(&key).map(|w| (play.name(), *w))
    }

    /// Its fitted sizes, `p=v` each, with `(+- se)` after each where `errors` asks.
    pub fn params_text(&self, errors: bool) -> String {
        let params: Vec<String> = self
            .params
            .iter()
            .map(|(k, v)| match self.std_err.get(k) {
                Some(e) if errors && e.is_finite() => format!("{k}={v:.4} (+- {e:.4})"),
                _ => format!("{k}={v:.4}"),
            })
            .collect();
        params.join(" ")
    }

    /// The effect set of this candidate on a rig (the parameter count depends on the rig).
    pub fn effects_on(&self, rig: &Rig) -> Effects {
        let mut fx = Effects::nominal();
        let (_, lens) = specs_of(rig, &self.kinds, None);
        apply_all(&self.kinds, &lens, &self.values, &mut fx);
        fx
    }
}

impl Diagnosis {
    /// The JSON the issue asks for (a superset).
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or(serde_json::Value::Null)
    }

    /// A readable report.
    pub fn summary(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "gap diagnosis, rig {}, {:.1} s, {} simulations in {:.1} s",
            self.rig, self.duration_s, self.simulations, self.elapsed_s
        );
        let f = &self.baseline;
        let _ = writeln!(
            s,
            "nominal model: GoF {:.1} % (output {:.1} %, effort {:.1} %), residual RMS output {:.4}, effort {:.4}; effort rel. error {:.2} %",
            100.0 * f.gof,
            100.0 * f.gof_output,
            100.0 * f.gof_effort,
            f.rms_output,
            f.rms_effort,
            f.effort_rel_error_pct
        );
        let r = &self.repeatability;
        let _ = writeln!(
            s,
            "repeatability: GoF {:.1} % (output {:.1} %, effort {:.1} %): the nominal model against itself on a reference moved by 1e-7 of its range, about as close as an exact model of this car can come",
            100.0 * r.gof,
            100.0 * r.gof_output,
            100.0 * r.gof_effort
        );
        let sc = &self.effort_scale;
        let _ = writeln!(
            s,
            "effort scale: x{:.3} the nominal model's (standard error {:.3}); beside a friction of the motion's sign x{:.3} ({:.3})",
            sc.factor,
            sc.standard_error,
            self.effort_scale_beside_friction.factor,
            self.effort_scale_beside_friction.standard_error
        );
        for (name, o) in [
            ("effort", &self.effort_offset),
            ("output", &self.output_offset),
        ] {
            let _ = writeln!(
                s,
                "{name} offset: {:+.3} (standard error {:.3}; {:.1} % of the {name}'s RMS {:.3}), in the {name}'s unit",
                o.mean,
                o.standard_error,
                100.0 * o.share_of_signal(),
                o.signal_rms
            );
        }
        if let Some(m) = &self.motor_ripple {
            let _ = writeln!(
                s,
                "against the motor's angle (the {} rows where it was slow): strongest line {:.3} at {} periods a turn, {:.1} times the other orders' median{}",
                m.rows,
                m.amplitude,
                m.periods_per_rev,
                m.ratio(),
                if m.stands_out() {
                    ": a torque that depends on where the rotor stands"
                } else {
                    ", no more than the residual gives any order"
                }
            );
        }
        if let Some(b) = &self.signature {
            let _ = writeln!(
                s,
                "torque balance ({}): play in the belt {:.2} +- {:.2} deg, Coulomb force at the rack {:.0} +- {:.0} N, belt stiffness {:.3} Nm/rad; {}",
                if b.against_model {
                    "the log's less the nominal model's on the same readout"
                } else {
                    "the log alone"
                },
                b.belt_play_deg,
                b.belt_play_se_deg,
                b.rack_coulomb_n,
                b.rack_coulomb_se_n,
                b.belt_stiffness_nm_rad,
                if b.holds {
                    "holds, so it rules candidates out and in".to_string()
                } else {
                    format!(
                        "not used on this log (a belt off Table 4's by more than {:.0} %, or a negative reading: the current is not read at the angles' instants, or the balance was turned off)",
                        100.0 * super::signature::STIFFNESS_TOLERANCE
                    )
                }
            );
        }
        let _ = writeln!(s, "\nwhere:");
        s.push_str(&self.where_.summary());
        // Ranked by what the fits minimise, the cost (each signal's residual over its noise),
        // printed as a share of the nominal cost; the GoF beside it need not fall in order.
        let _ = writeln!(s, "\nwhich (ranked by the cost left, % of the nominal):");
        let _ = writeln!(
            s,
            "  {:<28} {:>7} {:>7} {:>7} {:>7} {:>9}  params",
            "effect", "cost %", "GoF %", "out %", "eff %", "valid. %"
        );
        for c in &self.ranking {
            let _ = writeln!(
                s,
                "  {:<28} {:>7.1} {:>7.1} {:>7.1} {:>7.1} {:>9}  {}",
                c.effect,
                100.0 * c.cost / self.baseline_cost.max(1e-300),
                100.0 * c.gof,
                100.0 * c.fit.gof_output,
                100.0 * c.fit.gof_effort,
                c.gof_validation
                    .map_or("-".into(), |g| format!("{:.1}", 100.0 * g)),
                c.params_text(false)
            );
        }
        let v = &self.verdict;
        let ratio = self.baseline_cost / self.noise_floor_cost.max(1e-300);
        let _ = writeln!(
            s,
            "\nverdict: {}",
            match v.kind {
                // Only a residual at the noise (within a fifth) is "explained"; between that
                // and the unexplained bar the numbers say so.
                VerdictKind::None if ratio <= 1.2 => format!(
                    "none: the nominal model explains the log down to its noise floor \
                     (cost {ratio:.2} x floor)"
                ),
                VerdictKind::None => format!(
                    "none: no candidate effect is clearly present; the nominal residual is \
                     {ratio:.2} x the noise floor"
                ),
                VerdictKind::Unexplained => format!(
                    "unexplained: the nominal residual is {ratio:.2} x the noise floor and no \
                     candidate removes enough of it"
                ),
                VerdictKind::Effects => v.effects.join(" + "),
                VerdictKind::Parameters => {
                    "parameters: Table 4 refitted explains the log better than any effect"
                        .to_string()
                }
            }
        );
        if let Some(named) = &v.fitted {
            let _ = writeln!(s, "  fitted: {} {}", named.effect, named.params_text(true));
            if named.kinds.contains(&EffectKind::CurrentDelay) {
                let _ = writeln!(s, "  {CURRENT_LATE}");
            }
            if let (Some((_, w)), Some(b)) = (
                named.play_deg(),
                self.signature.as_ref().filter(|b| b.holds),
            ) {
                let line =
                    play_beside_balance(w, b.belt_play_deg, b.belt_play_se_deg, b.against_model);
                let _ = writeln!(s, "  {line}");
            }
        }
        let _ = writeln!(s, "  {}", v.reason);
        let _ = writeln!(
            s,
            "  GoF {:.1} % -> {:.1} % (output {:.1} -> {:.1} %, effort {:.1} -> {:.1} %); effort rel. error {:.2} -> {:.2} %",
            100.0 * self.baseline_gof,
            100.0 * v.gof_after,
            100.0 * self.baseline.gof_output,
            100.0 * v.fit_after.gof_output,
            100.0 * self.baseline.gof_effort,
            100.0 * v.fit_after.gof_effort,
            self.baseline.effort_rel_error_pct,
            v.fit_after.effort_rel_error_pct
        );
        if let (Some(b), Some(a)) = (&self.baseline_validation, &v.fit_validation) {
            let _ = writeln!(
                s,
                "  validation log: GoF {:.1} % -> {:.1} %; effort rel. error {:.2} -> {:.2} %",
                100.0 * b.gof,
                100.0 * a.gof,
                b.effort_rel_error_pct,
                a.effort_rel_error_pct
            );
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn named(kinds: &[EffectKind], params: &[(&str, f64)]) -> Candidate {
        Candidate {
            effect: kinds.iter().map(|k| k.name()).collect::<Vec<_>>().join("+"),
            kinds: kinds.to_vec(),
            params: params.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            ..Candidate::default()
        }
    }

    #[test]
    fn the_play_a_verdict_names_is_read_alone_or_in_a_pair() {
        let belt = named(&[EffectKind::BeltPlay], &[("width_deg", 1.7)]);
        assert_eq!(belt.play_deg(), Some(("backlash_belt", 1.7)));
        let pair = named(
            &[EffectKind::TireDahl, EffectKind::Backlash],
            &[
                ("backlash.width_deg", 0.76),
                ("tire_ground_dahl.force_n", 271.0),
            ],
        );
        assert_eq!(pair.play_deg(), Some(("backlash", 0.76)));
        // No play named: none read, whatever else the fit has.
        assert_eq!(
            named(&[EffectKind::Delay], &[("delay_ms", 30.0)]).play_deg(),
            None
        );
        assert_eq!(
            named(
                &[EffectKind::TireGround],
                &[("force_n", 1.0), ("width_deg", 2.0)]
            )
            .play_deg(),
            None
        );
    }

    #[test]
    fn a_fit_and_a_balance_apart_by_more_than_a_fifth_leave_the_size_uncertain() {
        let line = play_beside_balance(1.70, 1.26, 0.02, false);
        assert!(line.contains("differ by 26 %"), "{line}");
        assert!(!line.contains("agree"), "{line}");
        assert!(line.contains("the log alone"), "{line}");
        let line = play_beside_balance(1.05, 1.0, 0.05, true);
        assert!(line.contains("agree within 20 %"), "{line}");
        assert!(!line.contains("differ"), "{line}");
        assert!(line.contains("less the nominal model's"), "{line}");
    }
}
