//! The Table V workload shared by the examples: the model's first keyframe (else its reference
//! pose) and deterministic controls uniform in each actuator's control range, or, with
//! `UKEMI_CTRLS=FILE`, each step's controls from FILE (one step per line, separated by commas or
//! white space: e.g. the Python benchmark's `np.savetxt(FILE, ctrls, delimiter=",")`).
use ukemi_engine::{Model, State, mjcf, set_minimal};

/// The MJCF model at `path` with Table V's time step, 0.01 s.
pub fn load(path: &str) -> Model {
    let model = mjcf::load_path(std::path::Path::new(path)).unwrap().model;
    let mut opts = model.options.clone();
    opts.timestep = 0.01;
    model.with_options(opts).unwrap()
}

/// `../shared/models/NAME.xml` loaded as [`load`] does, or `None` (with a note on stderr) where
/// the shared folder is absent: the tests that read it skip then.
#[allow(dead_code)] // (the tests' helper: the examples take a path)
pub fn shared(name: &str) -> Option<Model> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(format!("../../shared/models/{name}.xml"));
    if !path.exists() {
        eprintln!("skipped: {} not found", path.display());
        return None;
    }
    Some(load(path.to_str()?))
}

/// The state at the model's first keyframe, else at `qpos0` at rest.
pub fn start_state(model: &Model) -> State {
    let mut state = State::reference(model);
    let (qpos, qvel) = match model.keyframes.first() {
        Some(k) => (k.qpos.clone(), k.qvel.clone()),
        None => (model.qpos0.clone(), vec![0.0; model.nv]),
    };
    set_minimal(model, &mut state, &qpos, &qvel).unwrap();
    state
}

/// The rows of numbers in the file at `path`, one per line, separated by commas or white space.
pub fn read_rows(path: &str) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    text.lines()
        .map(|l| {
            l.split(|c: char| c == ',' || c.is_whitespace())
                .filter(|x| !x.is_empty())
                .map(|x| x.parse().unwrap())
                .collect()
        })
        .collect()
}

/// Deterministic controls (a 64-bit LCG), uniform in each control range ([-1, 1] if unlimited).
pub struct Controls {
    seed: u64,
    /// The rows of `UKEMI_CTRLS` and the next one to return.
    rows: Option<(Vec<Vec<f64>>, usize)>,
}

impl Controls {
    pub fn new() -> Self {
        Self::with_seed(12345)
    }

    /// Another deterministic sequence.
    pub fn with_seed(seed: u64) -> Self {
        let rows = std::env::var("UKEMI_CTRLS")
            .ok()
            .map(|f| (read_rows(&f), 0));
        Controls { seed, rows }
    }

    /// The next control vector.
    pub fn next(&mut self, model: &Model) -> Vec<f64> {
        if let Some((rows, k)) = &mut self.rows {
            let row = rows
                .get(*k)
                .unwrap_or_else(|| panic!("UKEMI_CTRLS: no controls for step {k}"))
                .clone();
            assert_eq!(
                row.len(),
                model.nu(),
                "UKEMI_CTRLS: step {k} has {} controls, the model {}",
                row.len(),
                model.nu()
            );
            *k += 1;
            return row;
        }
        model
            .actuators
            .iter()
            .map(|a| {
                self.seed = self
                    .seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let u = (self.seed >> 11) as f64 / (1u64 << 53) as f64;
                let (lo, hi) = a.ctrlrange.unwrap_or((-1.0, 1.0));
                lo + (hi - lo) * u
            })
            .collect()
    }
}
