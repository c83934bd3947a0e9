//! Hard steps kept as snapshots (`tests/fixtures/NAME.txt`, written by
//! `examples/snapshot_step.rs`), shared by the integration tests that step them. The including
//! test declares `workload` (`examples/common/workload.rs`) beside this module.
use ukemi_engine::{Model, State};

/// The hard step kept in `tests/fixtures/NAME.txt`: the shared robot's model with the default
/// options (or `None` without `../shared`), the state before the step bit for bit (warm start
/// included), and the step's controls. Kept as snapshots, not replayed: a solver change moves
/// a chaotic trajectory's later states, and the replayed step was then no longer the hard one.
pub fn fixture(name: &str) -> Option<(Model, State, Vec<f64>)> {
    let path = format!("{}/tests/fixtures/{name}.txt", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let field = |key: &str| -> Vec<String> {
        let line = text.lines().find_map(|l| l.strip_prefix(key)).unwrap();
        line.split_whitespace().map(str::to_owned).collect()
    };
    let model = super::workload::shared(&field("robot ")[0])?;
    let numbers = |key| -> Vec<f64> { field(key).iter().map(|x| x.parse().unwrap()).collect() };
    let state = State::from_snapshot(&model, &numbers("state ")).unwrap();
    Some((model, state, numbers("ctrl ")))
}
