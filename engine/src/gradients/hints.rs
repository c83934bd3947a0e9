//! Warm starts handed from one flat step to the next.
//!
//! A flat state `x = [qpos, qvel]` carries no solver warm start, so a policy stepping
//! `ukemi.jax.step` / `ukemi.torch.step` in a loop would start every contact solve cold (the
//! Panda takes 2.2× the interior-point iterations per step that a rollout takes). Each flat
//! step therefore remembers its next state's warm start (joint impulses and interior-point
//! variables) under the exact bits of the `x⁺` it returns and the model; a flat step whose
//! input is such an `x⁺` starts where the step that made it ended, as a rollout does.
//!
//! The hint only moves the solver's starting point: the step solves the same equations to the
//! same tolerance, so its result is the same to within that tolerance (not bit for bit) as a
//! cold start's. Given the same sequence of calls the results are the same bits (hints are
//! read, never consumed). [`set_enabled`]`(false)` makes every flat step start cold. At most
//! `BUDGET` bytes are held; the oldest go first.
use std::collections::{HashMap, VecDeque};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use super::kept::Key;
use crate::model::Model;
use crate::state::State;

/// Most bytes of hints: ~13 kB each for the shared Panda (835 contact candidates, each keeping
/// its gap), so a few thousand steps or one step of a few thousand batched environments.
pub(crate) const BUDGET: usize = 64 << 20;

/// A state's warm start, with the interior-point variables stored sparsely (an inactive
/// contact candidate keeps only its gap).
struct Hint {
    joint_impulse: Vec<f64>,
    ineq_len: usize,
    ineq: Vec<(u32, f64)>,
}

impl Hint {
    fn of(s: &State) -> Hint {
        let ineq = s
            .ineq_vars
            .iter()
            .enumerate()
            .filter(|(_, v)| v.to_bits() != 0)
            .map(|(i, &v)| (i as u32, v))
            .collect();
        Hint {
            joint_impulse: s.joint_impulse.clone(),
            ineq_len: s.ineq_vars.len(),
            ineq,
        }
    }

    fn bytes(&self, key: &Key) -> usize {
        8 * self.joint_impulse.len() + 16 * self.ineq.len() + key.heap_bytes() + 128
    }

    fn apply(&self, s: &mut State) {
        if s.joint_impulse.len() != self.joint_impulse.len() || s.ineq_vars.len() != self.ineq_len {
            return; // another topology under a colliding key: start cold
        }
        s.joint_impulse.copy_from_slice(&self.joint_impulse);
        s.ineq_vars.fill(0.0);
        for &(i, v) in &self.ineq {
            s.ineq_vars[i as usize] = v;
        }
    }
}

struct Hints {
    by_hash: HashMap<u64, (Key, Hint, usize, u64)>,
    /// `(hash, serial)` in insertion order; an entry replaced since is skipped on eviction.
    order: VecDeque<(u64, u64)>,
    bytes: usize,
    serial: u64,
}

static HINTS: Mutex<Option<Hints>> = Mutex::new(None);
static ENABLED: AtomicBool = AtomicBool::new(true);
static HITS: AtomicUsize = AtomicUsize::new(0);
static MISSES: AtomicUsize = AtomicUsize::new(0);

fn with<R>(f: impl FnOnce(&mut Hints) -> R) -> R {
    // a panic while holding the lock leaves nothing half-done worth refusing
    let mut g = HINTS
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    f(g.get_or_insert_with(|| Hints {
        by_hash: HashMap::new(),
        order: VecDeque::new(),
        bytes: 0,
        serial: 0,
    }))
}

/// Whether flat steps hand their warm starts on (the default); returns the previous setting.
/// Turning it off also drops the hints held.
pub fn set_enabled(on: bool) -> bool {
    let was = ENABLED.swap(on, Ordering::Relaxed);
    if !on {
        clear();
    }
    was
}

/// Whether flat steps hand their warm starts on.
pub fn enabled() -> bool {
    ENABLED.load(Ordering::Relaxed)
}

/// Remember `next`'s warm start under the flat state `x_next` it was returned as.
pub(crate) fn remember(model: &Model, x_next: &[f64], next: &State) {
    if !enabled() {
        return;
    }
    let key = Key::new(model, x_next, &[]);
    let hint = Hint::of(next);
    let bytes = hint.bytes(&key);
    if bytes > BUDGET {
        return;
    }
    let dropped = with(|h| {
        let mut dropped = Vec::new();
        h.serial += 1;
        let serial = h.serial;
        let hash = key.hash();
        if let Some(old) = h.by_hash.insert(hash, (key, hint, bytes, serial)) {
            h.bytes -= old.2;
            dropped.push(old);
        }
        h.order.push_back((hash, serial));
        h.bytes += bytes;
        while h.bytes > BUDGET {
            let Some((hash, serial)) = h.order.pop_front() else {
                break;
            };
            if h.by_hash.get(&hash).is_some_and(|e| e.3 == serial)
                && let Some(old) = h.by_hash.remove(&hash)
            {
                h.bytes -= old.2;
                dropped.push(old);
            }
        }
        // replaced entries leave stale order records; drop them once they dominate
        if h.order.len() > 2 * h.by_hash.len() + 64 {
            let live = &h.by_hash;
            h.order
                .retain(|(hash, serial)| live.get(hash).is_some_and(|e| e.3 == *serial));
        }
        dropped
    });
    drop(dropped); // freed outside the lock
}

/// Give `s` (the state of flat `x`) the warm start remembered for `x`, if any.
pub(crate) fn recall(model: &Model, x: &[f64], s: &mut State) {
    if !enabled() {
        return;
    }
    let key = Key::new(model, x, &[]);
    let found = with(|h| match h.by_hash.get(&key.hash()) {
        Some((k, hint, _, _)) if *k == key => {
            hint.apply(s);
            true
        }
        _ => false,
    });
    let counter = if found { &HITS } else { &MISSES };
    counter.fetch_add(1, Ordering::Relaxed);
}

/// `(hits, misses, hints held, bytes held)` since the process started (for tests and
/// profiling).
pub fn stats() -> (usize, usize, usize, usize) {
    let (n, bytes) = with(|h| (h.by_hash.len(), h.bytes));
    (
        HITS.load(Ordering::Relaxed),
        MISSES.load(Ordering::Relaxed),
        n,
        bytes,
    )
}

/// Drop every hint.
pub fn clear() {
    let old = with(|h| {
        h.order.clear();
        h.bytes = 0;
        std::mem::take(&mut h.by_hash)
    });
    drop(old);
}

#[cfg(test)]
mod tests {
    use super::super::rollout::advance;
    use super::super::tangent::Coordinates;
    use super::super::{flat, test_scenes};
    use super::*;
    use crate::state::Workspace;

    /// The pushed box, moved 0.123 m along x so that no other test steps the same flat
    /// states (the hints are shared by the whole process): `(model, x0)`.
    fn own_box() -> (Model, Vec<f64>) {
        let (m, s) = test_scenes::pushed_box();
        let mut x = vec![0.0; flat::nx(&m)];
        flat::flat_of(&m, &s, &mut x);
        x[0] += 0.123;
        (m, x)
    }

    /// A flat step starts where the flat step that returned its input ended: the same bits as
    /// stepping its state with the warm start of the full state a rollout would carry.
    #[test]
    fn a_flat_step_starts_where_the_step_that_returned_its_input_ended() {
        let (m, mut x) = own_box();
        let mut ws = Workspace::new(&m);
        let mut full = flat::warm_state_of(&m, &x).unwrap();
        for k in 0..15 {
            let u = [test_scenes::push(k)];
            let next = flat::step(&m, &x, &u).unwrap();
            let mut s = flat::state_of(&m, &x).unwrap();
            s.joint_impulse.clone_from(&full.joint_impulse);
            s.ineq_vars.clone_from(&full.ineq_vars);
            full = advance(&m, &s, &u, Coordinates::Minimal, &mut ws).unwrap();
            let mut want = vec![0.0; x.len()];
            flat::flat_of(&m, &full, &mut want);
            assert!(
                next.iter()
                    .zip(&want)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "step {k}"
            );
            x = next;
        }
    }

    /// Chained flat steps take fewer interior-point iterations than cold starts from the same
    /// states, and reach the same states to within the solver's tolerance.
    #[test]
    fn warm_chained_flat_steps_take_fewer_iterations_to_the_same_states() {
        let (m, x0) = own_box();
        let mut ws = Workspace::new(&m);
        let (mut x, mut warm, mut cold) = (x0.clone(), 0, 0);
        for k in 0..25 {
            let u = [test_scenes::push(k)];
            let mut s = flat::warm_state_of(&m, &x).unwrap();
            warm += crate::step(&m, &mut s, &mut ws, &u).unwrap().iterations;
            let mut c = flat::state_of(&m, &x).unwrap();
            cold += crate::step(&m, &mut c, &mut ws, &u).unwrap().iterations;
            let (next, code) = flat::step_with_status(&m, &x, &u).unwrap();
            assert_eq!(code, 0);
            let mut from_cold = vec![0.0; x.len()];
            flat::flat_of(&m, &c, &mut from_cold);
            let (diff, scale) = test_scenes::max_diff(&next, &from_cold);
            assert!(diff <= 1e-7 * scale, "step {k}: {diff:e}");
            x = next;
        }
        assert!(2 * warm < cold, "warm {warm} cold {cold} iterations");
    }
}
