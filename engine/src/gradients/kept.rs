//! Forward rollouts kept for the reverse sweep that follows them.
//!
//! Under differentiation JAX and torch call a rollout (or a step) and later its VJP with the
//! same inputs (`x0`, `us`, the model); the VJP would solve every step again. A rollout or step
//! made with `keep` stores its states and solutions here under those inputs, bit for bit, and
//! `take` hands them to the VJP, which then only linearises (a rollout's steps all at once on
//! the thread pool). At most `BUDGET` bytes are held; the oldest go first.
use std::collections::VecDeque;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use super::StoredStep;
use crate::model::Model;
use crate::model::Options;
use crate::state::State;

/// Most bytes of kept rollouts: a 1000-step rollout of the shared A1 is 0.16 GB (every contact
/// candidate's interior-point variables, in each state and each solution), of the humanoid
/// 0.03 GB, of the Panda 0.13 GB (measured with `_kept_rollouts`).
pub(crate) const BUDGET: usize = 256 << 20;

/// A forward pass: the states `x_0..=x_T` and each step's stored solution.
pub(crate) struct Forward {
    pub states: Vec<State>,
    pub solutions: Vec<StoredStep>,
}

impl Forward {
    fn bytes(&self) -> usize {
        let s: usize = self.states.iter().map(State::heap_bytes).sum();
        s + self
            .solutions
            .iter()
            .map(StoredStep::heap_bytes)
            .sum::<usize>()
    }
}

/// The inputs a rollout's result depends on, compared bit for bit: the model (its structure by
/// [`Model::topology_id`], which only [`Model::with_params`] and [`Model::with_options`] keep
/// while changing anything, hence its parameters and options), `x0` and `us`.
#[derive(PartialEq)]
pub(crate) struct Key {
    /// A hash of the rest, compared first (a JAX scan keeps one step per iteration).
    hash: u64,
    topology: u64,
    options: Options,
    params: Vec<u64>,
    x0: Vec<u64>,
    us: Vec<u64>,
}

impl Key {
    pub(crate) fn new(model: &Model, x0: &[f64], us: &[f64]) -> Key {
        use std::hash::{Hash, Hasher};
        let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<u64>>();
        let (params, x0, us) = (bits(&model.params()), bits(x0), bits(us));
        let mut h = std::collections::hash_map::DefaultHasher::new();
        (model.topology_id(), &params, &x0, &us).hash(&mut h);
        Key {
            hash: h.finish(),
            topology: model.topology_id(),
            options: model.options.clone(),
            params,
            x0,
            us,
        }
    }

    /// The hash the key was made with.
    pub(crate) fn hash(&self) -> u64 {
        self.hash
    }

    /// Bytes of the key's arrays.
    pub(crate) fn heap_bytes(&self) -> usize {
        8 * (self.params.len() + self.x0.len() + self.us.len())
    }
}

struct Kept {
    entries: VecDeque<(Key, Forward, usize)>,
    bytes: usize,
}

static KEPT: Mutex<Kept> = Mutex::new(Kept {
    entries: VecDeque::new(),
    bytes: 0,
});
static HITS: AtomicUsize = AtomicUsize::new(0);
static MISSES: AtomicUsize = AtomicUsize::new(0);

fn with<R>(f: impl FnOnce(&mut Kept) -> R) -> R {
    // a panic while holding the lock leaves nothing half-done worth refusing
    let mut g = KEPT
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    f(&mut g)
}

/// Keep `forward` under `key` (not if it alone exceeds the budget), dropping the oldest
/// rollouts beyond the budget.
pub(crate) fn keep(key: Key, forward: Forward) {
    let bytes = forward.bytes();
    if bytes > BUDGET {
        return;
    }
    let dropped = with(|k| {
        let mut dropped = Vec::new();
        while k.bytes + bytes > BUDGET {
            let Some(old) = k.entries.pop_front() else {
                break;
            };
            k.bytes -= old.2;
            dropped.push(old);
        }
        k.entries.push_back((key, forward, bytes));
        k.bytes += bytes;
        dropped
    });
    drop(dropped); // freed outside the lock
}

/// The rollout kept under `key`, removed from the store (a VJP consumes its forward pass).
pub(crate) fn take(key: &Key) -> Option<Forward> {
    let found = with(|k| {
        let i = k.entries.iter().position(|(kk, _, _)| kk == key)?;
        let (_, forward, bytes) = k.entries.remove(i)?;
        k.bytes -= bytes;
        Some(forward)
    });
    let counter = if found.is_some() { &HITS } else { &MISSES };
    counter.fetch_add(1, Ordering::Relaxed);
    found
}

/// `(hits, misses, rollouts kept, bytes kept)` since the process started (for tests and
/// profiling).
pub fn stats() -> (usize, usize, usize, usize) {
    let (n, bytes) = with(|k| (k.entries.len(), k.bytes));
    (
        HITS.load(Ordering::Relaxed),
        MISSES.load(Ordering::Relaxed),
        n,
        bytes,
    )
}

/// Drop every kept rollout.
pub fn clear() {
    let entries = with(|k| {
        k.bytes = 0;
        std::mem::take(&mut k.entries)
    });
    drop(entries);
}

#[cfg(test)]
mod tests {
    use super::super::{flat, test_scenes};
    use super::*;

    /// The pushed box in flat form: `(model, x0, us)` of 25 steps.
    fn pushed_box() -> (Model, Vec<f64>, Vec<f64>) {
        let (m, s) = test_scenes::pushed_box();
        let mut x0 = vec![0.0; flat::nx(&m)];
        flat::flat_of(&m, &s, &mut x0);
        let us = (0..25).map(test_scenes::push).collect();
        (m, x0, us)
    }

    /// A kept rollout returns the same states, and the VJP that takes it gives the adjoints
    /// the VJP that solves the rollout again gives (the same bits: the same steps solved the
    /// same way), on one thread or two.
    #[test]
    fn a_kept_rollout_gives_the_same_states_and_adjoints() {
        let (m, x0, us) = pushed_box();
        let n = flat::nx(&m);
        let g: Vec<f64> = (0..26 * n).map(|i| (i as f64 * 0.37).cos()).collect();
        let plain = flat::rollout(&m, &x0, &us, 25).unwrap();
        let fresh = flat::rollout_vjp(&m, &x0, &us, 25, &g, Some(1e-4), true).unwrap();
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        for pool in [None, Some(&one)] {
            let kept = flat::rollout_kept(&m, &x0, &us, 25, true).unwrap();
            assert!(
                kept.iter()
                    .zip(&plain)
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            );
            let hits = stats().0;
            let vjp = || flat::rollout_vjp(&m, &x0, &us, 25, &g, Some(1e-4), true).unwrap();
            let r = match pool {
                Some(p) => p.install(vjp),
                None => vjp(),
            };
            assert!(stats().0 > hits, "the VJP took the kept rollout");
            for (a, b) in [(&r.0, &fresh.0), (&r.1, &fresh.1), (&r.2, &fresh.2)] {
                let (diff, scale) = test_scenes::max_diff(a, b);
                assert!(diff <= 1e-12 * scale, "{diff:e} of {scale:e}");
            }
        }
    }

    /// A kept step gives the same next state, and its VJP the adjoints of a fresh solve.
    #[test]
    fn a_kept_step_gives_the_same_next_state_and_adjoints() {
        let (m, x0, us) = pushed_box();
        let n = flat::nx(&m);
        let g: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).cos()).collect();
        let mut x = x0.clone();
        for (k, u) in us.iter().enumerate().take(12) {
            let u = [*u];
            let fresh = flat::step_vjp(&m, &x, &u, &g, None, true).unwrap();
            let plain = flat::step(&m, &x, &u).unwrap();
            let kept = flat::step_kept(&m, &x, &u, true).unwrap();
            assert!(
                kept.iter()
                    .zip(&plain)
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            );
            let hits = stats().0;
            let r = flat::step_vjp(&m, &x, &u, &g, None, true).unwrap();
            assert!(stats().0 > hits, "step {k}: the VJP took the kept step");
            for (a, b) in [(&r.0, &fresh.0), (&r.1, &fresh.1), (&r.2, &fresh.2)] {
                let (diff, scale) = test_scenes::max_diff(a, b);
                assert!(diff <= 1e-12 * scale, "step {k}: {diff:e} of {scale:e}");
            }
            x = plain;
        }
    }

    /// Other inputs or another model do not take a kept rollout; `take` removes it.
    #[test]
    fn a_kept_rollout_is_taken_only_with_its_inputs() {
        let (m, x0, us) = pushed_box();
        flat::rollout_kept(&m, &x0, &us, 25, true).unwrap();
        let mut other = us.clone();
        other[3] += 1e-12;
        assert!(take(&Key::new(&m, &x0, &other)).is_none());
        let heavier = {
            let mut p = m.params();
            p[0] *= 2.0;
            m.with_params(&p).unwrap()
        };
        assert!(take(&Key::new(&heavier, &x0, &us)).is_none());
        let looser = m
            .with_options(crate::Options {
                rtol: 1e-6,
                ..m.options.clone()
            })
            .unwrap();
        assert!(take(&Key::new(&looser, &x0, &us)).is_none());
        let f = take(&Key::new(&m, &x0, &us)).expect("kept");
        assert_eq!((f.states.len(), f.solutions.len()), (26, 25));
        assert!(take(&Key::new(&m, &x0, &us)).is_none(), "taken once");
    }
}
