//! κ's weight on each contact candidate and limit in the smoothed step of the gradients
//! (`kappa_grad`): a candidate's complementarity pairs are held at `b ∘ c = κ w e`, `w` falling
//! smoothly from 1 for a candidate touching at the step's start (within a tenth of its taper
//! distance, [`FULL`]) to [`WEIGHT_FLOOR`] at its taper distance ([`distance`]) and beyond.
//!
//! Why: a candidate that joins the smoothed step pushes with `κ w / gap`. With `w = 1` the
//! smoothed map jumped where a candidate came within the activation's reach: by `κ / gap` at
//! the reach (0.03 N·s at κ = 3e-4 and 1 cm), its Jacobian by `κ / gap²`. The taper distance
//! is a fixed fraction [`REACH_FRACTION`] of a smooth lower bound of that reach
//! (`margin + h (2 u + h |g|)`, [`super::activation::activate`]), so it grows with the approach
//! speed as the reach does: a fast candidate that will touch within the step weighs about 1
//! (its impact is smoothed; with a taper of the gap alone it weighed the floor, impacted
//! nearly hard in the smoothed step, and the matrix there was ill-conditioned). The smoothed
//! step holds every candidate above the floor ([`super::central::solve`] adds those the hard
//! step's corner rule left out), so a candidate crosses the activation's boundary with `w` at
//! its floor, zero slope and zero curvature: the map and its Jacobians change continuously.
//!
//! A joint limit's two sides are tapered alike, each by its slack at the start against
//! [`REACH_FRACTION`] of the limits' reach (`max(margin, 0.1) + 4 h |q̇|`,
//! [`limit_distance`]): untapered, a limit pushed with `κ / slack` as its joint came within
//! reach (3e-3 N·m·s at κ = 3e-4 and 0.1 rad). Tendon limits likewise, by the length's slack
//! and rate `Σ coef q̇` (below the activation's rate bound `Σ |coef q̇|`).
//!
//! `w` reads the gaps, slacks and rates at the step's start (the current configuration and
//! velocities): not the solve's variables, only the state and the model, whose partials then
//! carry `-κ ∂w/∂z` on the complementarity rows (`gradients::partials`).
use crate::model::Model;

use super::activation::candidate_margin;

/// κ's weight on a candidate far from touching: not 0, so that each pair keeps a strictly
/// interior central-path point, while the force it leaves at the reach (`κ · 1e-6 / gap`: 3e-8
/// N·s at κ = 3e-4 and 1 cm) is below any finite-difference resolution.
pub(crate) const WEIGHT_FLOOR: f64 = 1e-6;

/// Where the weight starts to fall, as a fraction of the taper distance: a candidate within a
/// tenth of it (0.82 mm at rest with the default margin and h = 0.01 s) weighs 1.
///
/// Why not 0: resting contacts sit at gaps of ~1e-11 m, and a weight whose second derivative
/// jumps there (as it must at the start of any taper) put the finite differences of every
/// resting contact's partials across the jump: `κ w'' ε / distance²`, 5e-6 at κ = 1e-4 on a
/// box resting on a plane against exact entries of 1e-9.
pub(crate) const FULL: f64 = 0.1;

/// The taper distance as a fraction of the activation's reach: below 1, so that a candidate
/// with the floor's weight cannot touch within the step (its travel, `h u + h² |g|`, stays
/// below `0.75 (margin + h² |g| + 2 h u)` for `h² |g| < 3 margin`: h up to 0.055 s at 1 cm).
pub(crate) const REACH_FRACTION: f64 = 0.75;

/// The approach speed (m/s) over which the reach's `max(u, 0)` is rounded ([`approach`]).
pub(crate) const SPEED_ROUNDING: f64 = 0.01;

/// What the weights read, at the step's start: each contact candidate's gap and its rate
/// (`Workspace`'s `contact_phi_now`, `contact_rate_now`), each limited coordinate's slacks
/// and rate (`limit_slack_now`, `limit_rate_now`, indexed from `limit_adr`). Built by
/// [`at_start`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct AtStart<'a> {
    pub phi: &'a [f64],
    pub rate: &'a [f64],
    pub limit_slack: &'a [[f64; 2]],
    pub limit_rate: &'a [f64],
    pub limit_adr: &'a [usize],
}

/// `Some(AtStart)` of a workspace when its κ is tapered (`kappa_taper`), borrowing only the
/// fields it reads (so that the caller may write the residual meanwhile).
macro_rules! at_start {
    ($ws:expr) => {
        $ws.kappa_taper.then_some($crate::solver::taper::AtStart {
            phi: &$ws.contact_phi_now,
            rate: &$ws.contact_rate_now,
            limit_slack: &$ws.limit_slack_now,
            limit_rate: &$ws.limit_rate_now,
            limit_adr: &$ws.limit_adr,
        })
    };
}
pub(crate) use at_start;

/// The weight at `m = gap / taper distance`: 1 up to [`FULL`], then
/// `floor + (1 - floor) (1 - S(t))` with `S(t) = t³ (10 - 15 t + 6 t²)` over
/// `t = (m - FULL) / (1 - FULL)`, to the floor at `m = 1`: continuous with its first two
/// derivatives at both ends (so central differences across them stay second-order accurate).
pub(crate) fn weight_at(m: f64) -> f64 {
    match ramp(m) {
        None => 1.0,
        Some(t) => {
            let s = t * t * t * (10.0 + t * (6.0 * t - 15.0));
            WEIGHT_FLOOR + (1.0 - WEIGHT_FLOOR) * (1.0 - s)
        }
    }
}

/// `d weight_at / dm` (0 where the weight is 1 or at its floor).
pub(crate) fn slope_at(m: f64) -> f64 {
    match ramp(m) {
        Some(t) if t < 1.0 => {
            -(1.0 - WEIGHT_FLOOR) * 30.0 * t * t * (1.0 - t) * (1.0 - t) / (1.0 - FULL)
        }
        _ => 0.0,
    }
}

/// `t` of [`weight_at`] for `m` (`None` below [`FULL`] or NaN; 1 from `m = 1`).
fn ramp(m: f64) -> Option<f64> {
    (m > FULL).then(|| ((m - FULL) / (1.0 - FULL)).min(1.0))
}

/// A smooth lower bound of `max(x, 0)` and its derivative: 0 for `x ≤ 0`, `x³ / (x² + τ²)`
/// above (τ = [`SPEED_ROUNDING`]), C² at 0 and within `τ / 2` of `x`.
fn approach(x: f64) -> (f64, f64) {
    if x <= 0.0 {
        return (0.0, 0.0);
    }
    let (x2, t2) = (x * x, SPEED_ROUNDING * SPEED_ROUNDING);
    let d = x2 + t2;
    (x * x2 / d, x2 * (x2 + 3.0 * t2) / (d * d))
}

/// Candidate `c`'s taper distance (m) at gap rate `rate` (m/s, negative approaching) and its
/// derivative in the rate: [`REACH_FRACTION`] of `margin + h² |g| + 2 h approach(-rate)`,
/// never above the activation's reach (infinite, no taper, when every candidate is always
/// active).
pub(crate) fn distance(model: &Model, c: usize, rate: f64) -> (f64, f64) {
    let h = model.options.timestep;
    let fixed = candidate_margin(model, &model.contacts[c]) + h * h * model.options.gravity.norm();
    let (u, du) = approach(-rate);
    let k = REACH_FRACTION;
    (k * (fixed + 2.0 * h * u), -2.0 * k * h * du)
}

/// Candidate `c`'s weight and its derivatives in the gap and in the gap rate at the start.
pub(crate) fn weight_and_slopes(model: &Model, c: usize, phi: f64, rate: f64) -> [f64; 3] {
    let (d, dd) = distance(model, c, rate);
    if !(d > 0.0 && d.is_finite()) {
        return no_room(d, phi);
    }
    let m = phi / d;
    let s = slope_at(m);
    [weight_at(m), s / d, -s * m * dd / d]
}

/// The weight where the taper distance `d` is infinite (every candidate and limit always
/// active: no taper) or NaN (kept active, the solve reports it): 1; where it is zero (an
/// activation margin of 0 without gravity: only the touching ones are within reach): 1
/// touching, the floor apart.
fn no_room(d: f64, gap: f64) -> [f64; 3] {
    let apart = d <= 0.0 && gap > 0.0;
    [if apart { WEIGHT_FLOOR } else { 1.0 }, 0.0, 0.0]
}

/// A limit side's taper distance at the rate `rate` of its coordinate and its derivative in
/// the rate: [`REACH_FRACTION`] of `max(margin, LIMIT_REACH) + 4 h a(rate)`, `a` a smooth lower
/// bound of `|rate|` (`√(rate² + τ²) - τ`), below the reach of the limits' activation
/// (`activation::activate_limits`: both sides of a coordinate by its speed).
pub(crate) fn limit_distance(model: &Model, rate: f64) -> (f64, f64) {
    let o = &model.options;
    let t = SPEED_ROUNDING;
    let root = rate.hypot(t);
    let k = REACH_FRACTION;
    let fixed = o.activation_margin.max(super::activation::LIMIT_REACH);
    (
        k * (fixed + 4.0 * o.timestep * (root - t)),
        4.0 * k * o.timestep * rate / root,
    )
}

/// A limit side's weight and its derivatives in the side's slack and in the coordinate's rate
/// (the upper side's slack `hi - q` falls as `q` rises, its distance reads `|q̇|` alike).
pub(crate) fn limit_weight_and_slopes(model: &Model, slack: f64, rate: f64) -> [f64; 3] {
    let (d, dd) = limit_distance(model, rate);
    if !(d > 0.0 && d.is_finite()) {
        return no_room(d, slack);
    }
    let m = slack / d;
    let s = slope_at(m);
    [weight_at(m), s / d, -s * m * dd / d]
}

/// κ's weight on the pair at node offset `o`, primal index `p` (the lower side of a limit for
/// `p = 0`), owned by `owner` (as [`super::inequality::for_each_owned_pair`] passes them: its
/// activation flag's index), with the gaps, slacks and rates at the step's start `start`
/// (`None`: no taper, weight 1).
pub(crate) fn weight(
    model: &Model,
    start: Option<AtStart>,
    owner: usize,
    o: usize,
    p: usize,
) -> f64 {
    let Some(s) = start else {
        return 1.0;
    };
    let (nc, nj) = (model.ncontact(), model.njoint());
    let k = if owner < nc {
        return weight_and_slopes(model, owner, s.phi[owner], s.rate[owner])[0];
    } else if owner < nc + nj {
        let j = owner - nc;
        let Some(node) = model.topology.limit_node[j] else {
            return 1.0;
        };
        s.limit_adr[j] + (o - model.topology.pattern.offset(node)) / 4
    } else if owner >= nc + nj + model.tendon_limits.len() {
        return 1.0; // dry friction: always within reach
    } else {
        // tendon limits follow the joints' limited coordinates
        s.limit_slack.len() - model.tendon_limits.len() + (owner - nc - nj)
    };
    limit_weight_and_slopes(model, s.limit_slack[k][p / 2], s.limit_rate[k])[0]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_weight_falls_from_one_to_its_floor_with_zero_slope_at_both_ends() {
        assert_eq!(weight_at(-1e-3), 1.0);
        assert_eq!(weight_at(f64::NAN), 1.0);
        assert_eq!(weight_at(FULL), 1.0);
        assert_eq!(weight_at(2.0), WEIGHT_FLOOR);
        assert!((weight_at(0.5 * (1.0 + FULL)) - 0.5 * (1.0 + WEIGHT_FLOOR)).abs() < 1e-15);
        let slope = |m: f64| (weight_at(m + 1e-7) - weight_at(m - 1e-7)) / 2e-7;
        let curve = |m: f64| (slope(m + 1e-4) - slope(m - 1e-4)) / 2e-4;
        for end in [FULL, 1.0] {
            assert!(slope(end).abs() < 1e-6, "{end}");
            assert!(curve(end).abs() < 1e-2, "{end}");
        }
        for m in [0.15, 0.37, 0.5, 0.9] {
            assert!((slope(m) - slope_at(m)).abs() < 1e-7, "{m}");
        }
        let mut last = 1.0;
        for i in 1..=100 {
            let w = weight_at(i as f64 / 100.0);
            assert!(w <= last && w >= WEIGHT_FLOOR);
            last = w;
        }
    }

    #[test]
    fn the_rounded_approach_is_below_the_speed_smooth_and_close() {
        let f = |x: f64| approach(x).0;
        for x in [-1.0, -1e-3, 0.0, 1e-4, 3e-3, 0.01, 0.05, 0.8, 10.0] {
            let (u, du) = approach(x);
            assert!(
                u <= x.max(0.0) && u >= x.max(0.0) - 0.5 * SPEED_ROUNDING,
                "{x}"
            );
            let fd = (f(x + 1e-8) - f(x - 1e-8)) / 2e-8;
            assert!((fd - du).abs() < 1e-6, "{x}: {fd} {du}");
        }
        // C² at 0: the curvature vanishes from both sides
        let curve = |x: f64| (f(x + 1e-5) - 2.0 * f(x) + f(x - 1e-5)) / 1e-10;
        assert!(curve(0.0).abs() < 0.5 && curve(1e-5).abs() < 2.0);
    }
}
