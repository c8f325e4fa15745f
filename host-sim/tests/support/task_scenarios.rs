//! Shared by the two task tests (`firmware_tasks`: direct drive, `epos4_tasks`: EPOS4 mode),
//! which run the same scenarios on `host_sim::firmware_fixture` with either controller: the
//! controller and plant a scenario runs, held by a test for its whole run, and the resting
//! steps of the settling test with its check.

use host_sim::effect_plant::PlantEffects;
use std::sync::{Mutex, MutexGuard};
use steering_ecu::controller::ControllerKind;

/// Held by a test that chooses the controller or the plant, for its whole run, so no other
/// test's scenario starts with its choice (tests that do not take it run paper mode).
static SCENARIOS: Mutex<()> = Mutex::new(());
/// The controller the next scenario's ECU runs.
static CONTROLLER: Mutex<ControllerKind> = Mutex::new(ControllerKind::Paper);
/// The plant the next scenario runs, if not the controller's default.
static PLANT_EFFECTS: Mutex<Option<PlantEffects>> = Mutex::new(None);

/// Chooses `kind` for the scenarios that follow, until the guard is dropped.
pub fn with_controller(kind: ControllerKind) -> MutexGuard<'static, ()> {
    let guard = SCENARIOS.lock().unwrap_or_else(|e| e.into_inner());
    set_controller(kind);
    guard
}

fn set_controller(kind: ControllerKind) {
    if let Ok(mut c) = CONTROLLER.lock() {
        *c = kind;
    }
}

/// Runs `scenario` once with each controller, holding the choice throughout so no other
/// test's scenario starts with this one's.
pub fn in_both_modes(scenario: impl Fn(ControllerKind)) {
    let _serial = SCENARIOS.lock().unwrap_or_else(|e| e.into_inner());
    for kind in [ControllerKind::Paper, ControllerKind::Ecu] {
        eprintln!("{kind:?} mode");
        set_controller(kind);
        scenario(kind);
    }
}

/// The controller the scenario's ECU runs.
pub fn controller() -> ControllerKind {
    CONTROLLER
        .lock()
        .map(|c| *c)
        .unwrap_or(ControllerKind::Paper)
}

/// The plant the scenario runs: the one a test chose, else for ECU mode the plant with belt
/// play and rack friction, as a car has them, and for paper mode the paper's linear plant,
/// its figures' own.
pub fn plant_effects(kind: ControllerKind) -> PlantEffects {
    match (PLANT_EFFECTS.lock().map(|e| *e).unwrap_or(None), kind) {
        (Some(effects), _) => effects,
        (None, ControllerKind::Paper) => PlantEffects::NONE,
        (None, ControllerKind::Ecu) => PlantEffects::PLAY_AND_FRICTION,
    }
}

/// Runs `scenario` on the plant with `effects` (with the controller already chosen).
pub fn on_plant<R>(effects: PlantEffects, scenario: impl FnOnce() -> R) -> R {
    if let Ok(mut e) = PLANT_EFFECTS.lock() {
        *e = Some(effects);
    }
    let r = scenario();
    if let Ok(mut e) = PLANT_EFFECTS.lock() {
        *e = None;
    }
    r
}

/// The resting steps of the settling test, deg at the wheel (from, to): both directions, small
/// and large, across straight ahead and not.
pub const STEPS_DEG: [(f32, f32); 6] = [
    (0.0, 5.0),
    (5.0, -5.0),
    (-5.0, 10.0),
    (10.0, -10.0),
    (-10.0, -8.0),
    (-8.0, 0.0),
];
/// How long each step of [`STEPS_DEG`] is held, periods of 10 ms.
pub const HOLD_PERIODS: usize = 250;

/// Appends the steps of [`STEPS_DEG`] to `script`, each at 4 deg per frame (the rate the
/// protocol allows) and held [`HOLD_PERIODS`]; `driving` makes an AS Driving period at an
/// angle. Where each hold starts, and its angle.
pub fn append_resting_steps<T: Clone>(
    script: &mut Vec<T>,
    driving: impl Fn(f32) -> T,
) -> Vec<(usize, f32)> {
    let mut holds = Vec::new();
    for (from, to) in STEPS_DEG {
        let n = ((to - from).abs() / 4.0).ceil() as usize;
        script.extend((1..=n).map(|k| driving(from + (to - from) * k as f32 / n as f32)));
        holds.push((script.len(), to));
        script.extend(vec![driving(to); HOLD_PERIODS]);
    }
    holds
}

/// Each hold of `holds` ends within 0.3 deg of its angle (`column_deg` per period), printed
/// with when the column stayed within 0.3 deg; `label` names the run.
pub fn assert_settled(label: &str, name: &str, column_deg: &[f64], holds: &[(usize, f32)]) {
    for &(start, to) in holds {
        let end = start + HOLD_PERIODS - 1;
        let error = |i: usize| column_deg[i] - f64::from(to);
        let settled = (start..=end)
            .rev()
            .take_while(|&i| error(i).abs() <= 0.3)
            .last();
        eprintln!(
            "{label}, {name}: step to {to} deg: {:+.3} deg after 2.5 s, within 0.3 deg from {} \
             ms on",
            error(end),
            settled.map_or(-1, |i| ((i - start) * 10) as i64)
        );
        assert!(
            error(end).abs() <= 0.3,
            "{name}: the column settled {:+.2} deg from {to} deg",
            error(end)
        );
    }
}
