//! What the diagnosis found on its way to the verdict, one [`Finding`] per step that decided
//! something, in the order the steps ran. The verdict's `reason` is their text joined by `; `:
//! the numbers live here, the sentences are made from them in one place.

use std::fmt;

/// Why an explanation is refused although the likelihood prefers it: eq. 11's GoF, what a team
/// reads, is below the nominal model's.
#[derive(Debug, Clone, PartialEq)]
pub enum Shortfall {
    /// On the log itself: the GoF with the explanation and without, as fractions.
    Log { after: f64, nominal: f64 },
    /// On the validation log.
    Validation { after: f64, nominal: f64 },
}

impl fmt::Display for Shortfall {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Shortfall::Log { after, nominal } => write!(
                f,
                "leaves the GoF at {:.1} %, below the nominal {:.1} %",
                100.0 * after,
                100.0 * nominal
            ),
            Shortfall::Validation { after, nominal } => write!(
                f,
                "leaves the validation GoF at {:.1} %, below the nominal {:.1} %",
                100.0 * after,
                100.0 * nominal
            ),
        }
    }
}

/// The best single candidate when nothing was named: its name, the share of the nominal cost
/// it removes, and whether it reached its minimum size.
#[derive(Debug, Clone, PartialEq)]
pub struct BestSingle {
    pub effect: String,
    pub improvement: f64,
    pub large_enough: bool,
}

/// One step's finding. Costs are the fits' (each residual sample over its noise, summed);
/// `share` and `gain_pct` fields are per cent of what the text says.
/// The signal a constant is left in ([`Finding::Offset`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OffsetOf {
    Effort,
    Output,
}

#[derive(Debug, Clone, PartialEq)]
pub enum Finding {
    /// The best single effect removes enough to be named.
    Named {
        effect: String,
        /// Share of the nominal cost it removes, a fraction.
        improvement: f64,
        nominal: f64,
        left: f64,
        floor: f64,
    },
    /// No single effect of its minimum size removes enough.
    NothingNamed {
        nominal: f64,
        floor: f64,
        best: Option<BestSingle>,
    },
    /// The best pair, refused: the best single with the log's stamping lag fitted beside it
    /// explains as much.
    PairLagExplains {
        pair: String,
        gain_pct: f64,
        best: String,
        lag_ms: f64,
        with_lag: f64,
        pair_cost: f64,
    },
    /// The best pair, refused: a pair whose second effect is below its minimum size leaves less.
    PairSecondUndersized {
        pair: String,
        gain_pct: f64,
        best: String,
        small: String,
        small_cost: f64,
    },
    /// The best pair, refused: with Table 4 refitted within its tolerance beside the best
    /// single, the pair removes too little.
    PairNotBeyondRefit {
        pair: String,
        gain_pct: f64,
        best: String,
        tolerance: f64,
        single: f64,
        with_pair: f64,
    },
    /// A second effect added to the best one.
    Added { added: String, gain_pct: f64 },
    /// A pair named that grew from the runner-up.
    PairNamed {
        pair: String,
        gain_pct: f64,
        best: String,
    },
    /// The best pair leaves more than the best single alone.
    PairLeavesMore {
        pair: String,
        best: String,
        pair_cost: f64,
    },
    /// The best pair removes too little of what the best single left.
    PairRemovesTooLittle {
        pair: String,
        gain_pct: f64,
        gain: f64,
    },
    /// The pair removes enough on the fit's window but leaves the whole log's GoF below the
    /// single's (fractions).
    PairLowersGof {
        pair: String,
        gain_pct: f64,
        best: String,
        pair_gof: f64,
        best_gof: f64,
    },
    /// The log's torque balance shows what the single named does not make, but no pair with
    /// it fits as the pair rule of [`Finding::DemandedByLog`] asks: the single stands alone.
    DemandedNotFitted {
        reading: &'static str,
        value: f64,
        standard_error: f64,
        unit: &'static str,
        single: String,
    },
    /// The best single was a tyre, the torque balance shows a Coulomb force at the rack and
    /// the rack friction's GoF on the whole log is no lower: the friction is the best instead.
    BalanceShowsFriction {
        tyre: String,
        tyre_gof: f64,
        friction: String,
        friction_gof: f64,
        reading: f64,
        standard_error: f64,
    },
    /// The best single left the log's GoF below the nominal one, the torque balance shows play
    /// in the belt and a play candidate leaves the GoF no lower: the play is the best instead
    /// (GoFs as fractions, the reading in deg).
    BalanceShowsPlay {
        best: String,
        best_gof: f64,
        play: String,
        play_gof: f64,
        nominal_gof: f64,
        reading: f64,
        standard_error: f64,
    },
    /// Table 4 refitted freely left the tolerance; what it moved and left, and the bounded refit.
    RefitFree {
        moved: Vec<String>,
        left: f64,
        tolerance: f64,
        within: f64,
    },
    /// The named effect still removes enough on top of Table 4 refitted within its tolerance.
    EffectOnRefit {
        tolerance: f64,
        refit: f64,
        effect: String,
        gain_pct: f64,
    },
    /// The named effect does not: it stood in for a car a few per cent off the table.
    EffectNotBeyondRefit {
        tolerance: f64,
        refit: f64,
        effect: String,
        effect_cost: f64,
        gain_pct: f64,
    },
    /// Table 4 refitted with the log's stamping lag, from starts far off the table.
    FarStarts {
        moved: Vec<String>,
        lag_ms: f64,
        left: f64,
        tolerance: f64,
        within: f64,
        wins: bool,
    },
    /// What the kept Table 4 refit leaves.
    RefitLeaves {
        left: f64,
        share_pct: f64,
        better_than_effects: bool,
    },
    /// The refit, refused by the GoF, and with it the effect it explained better.
    RefitWorse(Shortfall),
    /// The named effect, refused by the GoF.
    EffectWorse { effect: String, why: Shortfall },
    /// A signal's residual keeps a constant part that no effect and no Table 4 parameter
    /// makes (`score::effort_offset`, `score::output_offset`): a sensor's zero off, a logger's
    /// zero. The log is not the nominal car.
    Offset {
        /// Which signal keeps it.
        signal: OffsetOf,
        /// The intercept, the signal's unit.
        mean: f64,
        standard_error: f64,
        /// Of the logged signal's RMS, %.
        share_pct: f64,
    },
    /// The log's effort is a share off the nominal model's throughout (`score::effort_scale`):
    /// a torque constant or a current scale off, which no effect makes.
    EffortScale {
        factor: f64,
        standard_error: f64,
        /// Read with a friction of the motion's sign fitted beside it
        /// (`score::effort_scale_beside_friction`), where the plain slope fell short.
        beside_friction: bool,
    },
    /// The named effect has friction, but the log's current is a share above the model's in
    /// every part of the log (`score::effort_scale`, `FRICTION_FOR_SCALE_SIGNIFICANCE`):
    /// friction adds a fixed current, it does not scale it, so the friction stands in for a
    /// torque constant off.
    FrictionForScale {
        effect: String,
        factor: f64,
        standard_error: f64,
    },
    /// The effort's residual keeps a line at a whole number of periods a motor turn
    /// (`ripple::motor_ripple`): a torque that depends on where the rotor stands (cogging, a
    /// torque ripple), which no candidate effect and no Table 4 parameter makes.
    MotorRipple(super::ripple::MotorRipple),
    /// The log's own torque balance (`gap::signature`) shows less of what this candidate
    /// models than half the smallest size it is named at: it is not fitted, so it cannot
    /// stand in for another effect.
    RuledOutByLog {
        effect: String,
        /// What the balance reads, e.g. `play in the belt`.
        reading: &'static str,
        value: f64,
        standard_error: f64,
        unit: &'static str,
        /// Half the smallest size named, in `unit`.
        limit: f64,
    },
    /// The log's own torque balance shows more than the smallest named of what the single
    /// effect named does not make: the best pair that adds it is named.
    DemandedByLog {
        pair: String,
        reading: &'static str,
        value: f64,
        standard_error: f64,
        unit: &'static str,
        /// The single effect the pair replaces, and how much more the pair leaves, % (negative:
        /// less).
        single: String,
        more_pct: f64,
    },
    /// Nothing explains a log far above its floor: what to try.
    TryElse,
}

impl fmt::Display for Finding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Finding::Named {
                effect,
                improvement,
                nominal,
                left,
                floor,
            } => write!(
                f,
                "{} removes {:.0} % of the nominal cost ({:.0} of {:.0}; noise floor {:.0})",
                effect,
                100.0 * improvement,
                nominal - left,
                nominal,
                floor
            ),
            Finding::NothingNamed {
                nominal,
                floor,
                best,
            } => {
                write!(
                    f,
                    "the nominal cost is {:.2} times the noise floor ({:.0} of {:.0}); no effect \
                     of at least its minimum size removes enough of it (best: ",
                    nominal / floor.max(1e-300),
                    nominal,
                    floor,
                )?;
                if let Some(b) = best {
                    write!(
                        f,
                        "{} {:.0} %{}",
                        b.effect,
                        100.0 * b.improvement,
                        if b.large_enough {
                            ""
                        } else {
                            ", below its minimum size"
                        }
                    )?;
                }
                write!(f, ")")
            }
            Finding::PairLagExplains {
                pair,
                gain_pct,
                best,
                lag_ms,
                with_lag,
                pair_cost,
            } => {
                write!(
                    f,
                    "the pair {pair} removes {gain_pct:.0} % of what {best} leaves, but {best} \
                     with the log's stamps {lag_ms:.1} ms late (fitted) leaves {with_lag:.0}, \
                     and the pair "
                )?;
                if pair_cost < with_lag {
                    write!(
                        f,
                        "removes only {:.0} % of that",
                        100.0 * (with_lag - pair_cost) / with_lag.max(1e-300)
                    )?;
                } else {
                    write!(f, "leaves more ({pair_cost:.0})")?;
                }
                write!(f, ": not named")
            }
            Finding::PairSecondUndersized {
                pair,
                gain_pct,
                best,
                small,
                small_cost,
            } => write!(
                f,
                "the pair {pair} removes {gain_pct:.0} % of what {best} leaves, but {small} \
                 leaves less ({small_cost:.0}) with its second effect below its minimum size: \
                 not named"
            ),
            Finding::PairNotBeyondRefit {
                pair,
                gain_pct,
                best,
                tolerance,
                single,
                with_pair,
            } => write!(
                f,
                "the pair {pair} removes {gain_pct:.0} % of what {best} leaves, but with Table 4 \
                 refitted within x{tolerance:.1} beside {best} it removes only {:.0} % ({:.0} of \
                 {single:.0}): not named",
                100.0 * (single - with_pair) / single.max(1e-300),
                single - with_pair,
            ),
            Finding::Added { added, gain_pct } => {
                write!(f, "adding {added} removes {gain_pct:.0} % of what was left")
            }
            Finding::PairNamed {
                pair,
                gain_pct,
                best,
            } => write!(
                f,
                "the pair {pair} removes {gain_pct:.0} % of what {best} leaves"
            ),
            Finding::PairLeavesMore {
                pair,
                best,
                pair_cost,
            } => write!(
                f,
                "the best pair {pair} leaves more than {best} alone ({pair_cost:.0})"
            ),
            Finding::PairRemovesTooLittle {
                pair,
                gain_pct,
                gain,
            } => write!(
                f,
                "the best pair {pair} removes only {gain_pct:.0} % of what was left ({gain:.0})"
            ),
            Finding::PairLowersGof {
                pair,
                gain_pct,
                best,
                pair_gof,
                best_gof,
            } => write!(
                f,
                "the pair {pair} removes {gain_pct:.0} % of what {best} leaves on the fit's \
                 window but leaves the log's GoF at {:.1} %, below {best}'s {:.1} %: not named",
                100.0 * pair_gof,
                100.0 * best_gof
            ),
            Finding::DemandedNotFitted {
                reading,
                value,
                standard_error,
                unit,
                single,
            } => write!(
                f,
                "the log's torque balance shows {value:.2} +- {standard_error:.2} {unit} of \
                 {reading}, but no pair of {single} with it fits the log as well as {single} \
                 alone: {single} stands alone"
            ),
            Finding::BalanceShowsFriction {
                tyre,
                tyre_gof,
                friction,
                friction_gof,
                reading,
                standard_error,
            } => write!(
                f,
                "{tyre} left the least on the fit's window, but the log's torque balance shows \
                 {reading:.0} +- {standard_error:.0} N of Coulomb force at the rack and \
                 {friction} leaves the log's GoF at {:.1} % (the tyre {:.1} %): {friction} \
                 is the best single",
                100.0 * friction_gof,
                100.0 * tyre_gof
            ),
            Finding::BalanceShowsPlay {
                best,
                best_gof,
                play,
                play_gof,
                nominal_gof,
                reading,
                standard_error,
            } => write!(
                f,
                "{best} left the least on the fit's window but the log's GoF at {:.1} %, below \
                 the nominal {:.1} %; the log's torque balance shows {reading:.2} +- \
                 {standard_error:.2} deg of play in the belt and {play} leaves the GoF at \
                 {:.1} %: {play} is the best single",
                100.0 * best_gof,
                100.0 * nominal_gof,
                100.0 * play_gof
            ),
            Finding::RefitFree {
                moved,
                left,
                tolerance,
                within,
            } => write!(
                f,
                "Table 4 refitted freely moves {} and leaves {left:.0}, held within \
                 x{tolerance:.1} {within:.0}",
                moved.join(", ")
            ),
            Finding::EffectOnRefit {
                tolerance,
                refit,
                effect,
                gain_pct,
            } => write!(
                f,
                "Table 4 refitted within x{tolerance:.1} leaves {refit:.0}, and {effect} on top \
                 of it removes {gain_pct:.0} % of that"
            ),
            Finding::EffectNotBeyondRefit {
                tolerance,
                refit,
                effect,
                effect_cost,
                gain_pct,
            } => write!(
                f,
                "but Table 4 refitted within x{tolerance:.1} leaves {refit:.0}, no more than \
                 {effect} ({effect_cost:.0}), and {effect} on top of it removes only \
                 {gain_pct:.0} % of that: not named"
            ),
            Finding::FarStarts {
                moved,
                lag_ms,
                left,
                tolerance,
                within,
                wins,
            } => write!(
                f,
                "Table 4 with the log's stamps late (fitted), from starts far off the table \
                 (j_w x0.4 and x2.5, beta_sw x2.5, k_b x0.4 and x2.5), moves {} with the stamps \
                 {lag_ms:.1} ms late and leaves {left:.0}; held within x{tolerance:.1} it leaves {within:.0}{}",
                moved.join(", "),
                if *wins { "" } else { ": not named" }
            ),
            Finding::RefitLeaves {
                left,
                share_pct,
                better_than_effects,
            } => write!(
                f,
                "a refit of Table 4 leaves {left:.0} ({share_pct:.0} % of the nominal cost{})",
                if *better_than_effects {
                    ", better than any effect"
                } else {
                    ""
                }
            ),
            Finding::RefitWorse(why) => {
                write!(
                    f,
                    "the refit {why}: not named, nor the effect it explains better"
                )
            }
            Finding::EffectWorse { effect, why } => write!(f, "{effect} {why}: not named"),
            Finding::Offset {
                signal,
                mean,
                standard_error,
                share_pct,
            } => {
                let (name, cause) = match signal {
                    OffsetOf::Effort => ("effort", "a current sensor's offset, or a logger's zero"),
                    OffsetOf::Output => (
                        "output",
                        "a sensor's zero off (the column encoder's, on the paper rig)",
                    ),
                };
                write!(
                    f,
                    "the {name}'s residual keeps a constant {mean:+.3} ({:.0} standard errors, \
                     {share_pct:.1} % of the {name}'s RMS) that no candidate effect and no \
                     Table 4 parameter makes: {cause}",
                    mean.abs() / standard_error.max(1e-12)
                )
            }
            Finding::EffortScale {
                factor,
                standard_error,
                beside_friction,
            } => write!(
                f,
                "the effort is x{factor:.2} the nominal model's throughout ({:.0} standard \
                 errors{}), which no candidate effect makes: the motor's torque constant off \
                 Table 1, or the current logged in another scale",
                (factor - 1.0).abs() / standard_error.max(1e-12),
                if *beside_friction {
                    ", with a friction of the motion's sign fitted beside it"
                } else {
                    ""
                }
            ),
            Finding::FrictionForScale {
                effect,
                factor,
                standard_error,
            } => write!(
                f,
                "the effort is x{factor:.2} the nominal model's in every part of the log ({:.0} \
                 standard errors; a friction's share changes from one part to the next): \
                 friction adds a current of a fixed size and does not scale it, so {effect} \
                 stands in for a torque constant off: not named",
                (factor - 1.0).abs() / standard_error.max(1e-12)
            ),
            Finding::MotorRipple(line) => write!(
                f,
                "where the motor is slow, the effort's residual keeps {:.2} A at {} periods a \
                 motor turn ({:.1} times the other orders' median; at least {:.3} Nm at Table \
                 1's torque constant, as the loop counters only part of it where the motor \
                 moves): a torque that depends on where the rotor stands (cogging, a torque \
                 ripple), which no candidate effect and no Table 4 parameter makes",
                line.amplitude,
                line.periods_per_rev,
                line.ratio(),
                line.torque_nm
            ),
            Finding::RuledOutByLog {
                effect,
                reading,
                value,
                standard_error,
                unit,
                limit,
            } => write!(
                f,
                "the log's torque balance shows {value:.2} +- {standard_error:.2} {unit} of \
                 {reading}, under half the smallest named ({limit:.2} {unit}) by three standard \
                 errors: {effect} not fitted"
            ),
            Finding::DemandedByLog {
                pair,
                reading,
                value,
                standard_error,
                unit,
                single,
                more_pct,
            } => write!(
                f,
                "the log's torque balance shows {value:.2} +- {standard_error:.2} {unit} of \
                 {reading}, which {single} does not make: {pair} named (it leaves {:.0} % {} \
                 than {single} alone, within what a second effect must remove)",
                more_pct.abs(),
                if *more_pct >= 0.0 { "more" } else { "less" }
            ),
            Finding::TryElse => write!(
                f,
                "try `--refit-linear` (Table 4 off), other candidate effects (`--effects`), or \
                 check the log's columns and units"
            ),
        }
    }
}

/// The verdict's reason: the findings' text, in order, joined by `; `.
pub fn reason(findings: &[Finding]) -> String {
    findings
        .iter()
        .map(|f| f.to_string())
        .collect::<Vec<_>>()
        .join("; ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reason_joins_each_finding_in_order() {
        let findings = [
            Finding::Named {
                effect: "backlash".into(),
                improvement: 0.73,
                nominal: 1000.0,
                left: 270.0,
                floor: 24.0,
            },
            Finding::EffectWorse {
                effect: "backlash".into(),
                why: Shortfall::Validation {
                    after: 0.801,
                    nominal: 0.812,
                },
            },
        ];
        assert_eq!(
            reason(&findings),
            "backlash removes 73 % of the nominal cost (730 of 1000; noise floor 24); backlash \
             leaves the validation GoF at 80.1 %, below the nominal 81.2 %: not named"
        );
    }

    #[test]
    fn a_lag_that_explains_the_pair_says_whether_the_pair_still_removes_some() {
        let lag = |pair_cost| Finding::PairLagExplains {
            pair: "delay+tire_ground".into(),
            gain_pct: 40.0,
            best: "delay".into(),
            lag_ms: 2.5,
            with_lag: 100.0,
            pair_cost,
        };
        assert!(
            lag(90.0)
                .to_string()
                .contains("removes only 10 % of that: not named")
        );
        assert!(
            lag(120.0)
                .to_string()
                .contains("leaves more (120): not named")
        );
    }
}
