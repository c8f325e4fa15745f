//! Sim-to-real gap diagnosis: where a log departs from the nominal model (frequency band,
//! operating regime, segment of the chain, signal), which unmodelled effect explains it, and
//! how far the gap shrinks once that effect is added, checked on a second log.
//!
//! Theory of operation:
//!
//! ```text
//!  log --(rig columns, binned to the rig grid)--> Record
//!  Record.reference --> model + effects (closed loop, paper mode) --> output, effort
//!  residual = (simulated - measured) / ||measured - mean||, per signal, stacked
//!  nominal ---------------------------------------> baseline GoF, where (bands, regimes, segment)
//!  for each candidate effect: LM fit of its 1-2 parameters --> GoF, ranking
//!  verdict: best effect if it removes enough of the residual above the noise floor;
//!           then the best pair, if the pair removes enough of what is left
//! ```
//!
//! GoF is the paper's eq. 11 per signal; the combined figure is `1 - sqrt(mean (1 - GoF)^2)`
//! over the output and the effort, which is what the fits minimise.

pub mod chatter;
pub mod cli;
pub mod columns;
mod diagnose;
mod diagnosis;
pub mod drive;
pub mod drive_clock;
mod effects;
pub mod finding;
pub mod fit;
pub mod generator;
pub mod generator_epos4;
pub mod held;
pub mod identify;
pub mod locate;
pub mod model;
mod pairs;
pub mod plots;
mod record;
pub mod reference_window;
mod refits;
pub mod rig;
pub mod ripple;
pub mod rng;
mod rounded;
mod score;
mod search;
pub mod selftest;
pub mod signature;

pub use diagnose::{Screen, diagnose, screen};
pub use diagnosis::{CURRENT_LATE, Candidate, Diagnosis, Options, Verdict, VerdictKind};
pub use effects::EffectKind;
pub(crate) use record::interp_at;
pub use record::{CurrentSamples, LogTiming, Record, ReferenceConvention};
pub use score::{Fit, Noise, Offset, Scale, Scorer, combined_gof, repeatability, simulate};
pub use search::Progress;
pub(crate) use search::parallel_map;
