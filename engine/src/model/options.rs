//! Simulation and solver options, with documented defaults.
use nalgebra::Vector3;

/// Options of a model. Change them with [`crate::Model::with_options`].
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    /// Time step `h` (s). Default 0.01.
    pub timestep: f64,
    /// Gravity, world frame (m/s²). Default `(0, 0, -9.81)`.
    pub gravity: Vector3<f64>,
    /// Residual tolerance: the solve has converged when the ∞-norm of every residual row
    /// (momentum rows in N·s, constraint rows in m or quaternion units) is below it. Default 1e-10.
    pub rtol: f64,
    /// Maximum Newton / interior-point iterations per step (per solve attempt). Default 50
    /// (Dojo.jl's default).
    pub max_iter: usize,
    /// Extra interior-point iterations, beyond `max_iter`, for an attempt whose equality
    /// residual is below 1e-4 when it reaches `max_iter`: its complementarity endgame, where a
    /// stall often ends by itself, while a failed attempt costs the retries and subdivisions
    /// (see `solver::ipm::ENDGAME_RESIDUAL`). Default 150; 0 makes `max_iter` a hard cap.
    pub endgame_iter: usize,
    /// Maximum backtracking halvings per Newton iteration. Default 10.
    pub max_ls: usize,
    /// Complementarity (κ) tolerance of the interior-point solve: converged when every pair's
    /// `|b ∘ c| / max(1, |b|)` (b the impulse-like variable) is below it. It bounds contact softness: resting contacts hover at most
    /// `kappa_tol / γ` above the surface, and a box held by static friction creeps at a speed
    /// proportional to it. Default 1e-11.
    pub kappa_tol: f64,
    /// Acceptable residual: when the iteration stalls (no step length decreases the merit, or
    /// `max_iter` is reached) at an iterate whose residual is below this and whose
    /// complementarity is below `acceptable_kappa_tol`, the step ends with status
    /// `Acceptable` (a success) instead of a failure. The gap rows are residual rows, so this
    /// also bounds the penetration of an acceptable step. 0 turns acceptance off. Default 1e-8.
    pub acceptable_rtol: f64,
    /// Acceptable complementarity violation (see `acceptable_rtol`). Default 1e-8.
    pub acceptable_kappa_tol: f64,
    /// An attempt whose iterate stays acceptable (within `acceptable_rtol` and
    /// `acceptable_kappa_tol`) and within 100× of `rtol` and `kappa_tol` for this many
    /// consecutive iterations, over which its worst violation relative to `rtol` and
    /// `kappa_tol` did not halve, has stalled there: it ends as `Acceptable`, and so does the
    /// solve (the cold retries are for failures). IPOPT's `acceptable_iter`, with its default
    /// 15, plus the nearness and progress tests. 0 turns this off (an acceptable iterate then
    /// ends an attempt only when it stalls or reaches its budget, and the retries try for full
    /// convergence first, as every other acceptable attempt still does). Why: with `cone_gap`
    /// off, a finger pad sliding on the other pad holds the Jordan product's vector part of
    /// its friction cone near 3e-11 (the iterate's residual 1e-12, its mean complementarity
    /// 8e-13) and crawled towards `kappa_tol` for the whole 200-iteration budget, then through
    /// two cold retries that ended the same way (Panda, `step_bench` seed 12, step 261: 450 iterations). With
    /// `cone_gap` on, the same states (`option_ab MODEL.xml 300 SEED acceptable_iter 0 15`):
    /// Panda seed 10 2452 → 1798 iterations (1.58 → 0.50 s), seed 12 2431 → 2226, X2 seed 8
    /// 1294 → 908; the humanoid and the A1 unchanged.
    pub acceptable_iter: usize,
    /// An attempt whose worst violation relative to the tolerances (`max(r / rtol, k /
    /// kappa_tol)`) has not fallen tenfold below its best in this many iterations has stalled:
    /// it ends there (status `MaxIterations`), and the step goes on to its next retry (cold,
    /// wider activation, sub-steps). Default 20; 0 turns this off (an attempt then runs to
    /// `max_iter`, and past it into the endgame). The step's last resort (every candidate
    /// active, 4 × `max_iter`) is never cut. Why: when contacts slide with both members of a
    /// friction cone on their boundaries (the Panda's finger pads on the floor), every attempt
    /// of the retry ladder crawls at step lengths of ~1e-3, 50 iterations each and up to 150
    /// more in the endgame, before sub-steps solve the step: the Panda's seed-1 step 162 took
    /// 566 iterations, a third of its 300-step run's time. Measured on the same states
    /// (`option_ab MODEL.xml 300 SEED stall_iter 0 20`, seeds 1-8, seconds summed): Panda 1.632
    /// → 1.351 (seeds 1 and 3 0.529 → 0.326 and 0.430 → 0.307; seeds 2 and 5 0.112 → 0.135 and
    /// 0.189 → 0.212), humanoid 1.969 → 1.970, A1 1.364 → 1.399; no step failed either way.
    /// 15 cut too early (Panda 1.631 → 1.489, humanoid 2.014 → 2.084), 30 saved less (Panda
    /// 1.587 → 1.422).
    pub stall_iter: usize,
    /// Judge a friction cone's complementarity by its duality gap `bᵀc` alone (the scalar part
    /// of the Jordan product `b ∘ c`), as conic interior-point solvers do (ECOS, Clarabel), not
    /// also by the vector part `b₀c̄ + c₀b̄`. Default true. Why: for a sliding pair (impulse and
    /// slip both on their cone's boundary) the vector part measures how far the friction
    /// direction is from opposing the slip, and it shrinks only like the square root of the
    /// gap; `kappa_tol` on it demanded the direction to ~1e-11 rad, and the Panda's pressed
    /// finger pads crawled towards it for hundreds of iterations. Measured on the same states
    /// (`option_ab MODEL.xml 300 SEED cone_gap 0 1`, seeds 5..12): Panda seed 10 2766 → 1833
    /// iterations (its step 250 converged in 16 instead of failing for 800 and being
    /// subdivided), seed 9 1745 → 1562, X2 seed 8 1088 → 904, A1 seed 8 4939 → 4724, the
    /// humanoid 0.3-2.4% fewer; Panda seed 11 3581 → 3756. A sliding box's friction opposes
    /// its slip to 1e-8 either way (`tests/test_contact.py`).
    pub cone_gap: bool,
    /// Hold at zero the friction of a contact between two bodies that can only slide along the
    /// contact normal relative to each other (a parallel gripper's finger pads pressed
    /// together, [`crate::contact::slide_pair`]), and of such contacts between the same two
    /// bodies along the same normal solve only the tightest, which implies the others. Default
    /// true. Such a contact cannot slip: its friction only trades places with the joints'
    /// reactions and never changes the motion, but it leaves the solve a family of solutions,
    /// which jammed the Panda's solves. Also holds at zero, during a hard solve's first
    /// attempt, the friction of active candidates at least 1 mm apart while their gap stays
    /// open (`solver::saturation::hold_separated`): apart, a contact has no friction, and its
    /// slip member turning with the velocities cut the first iterations (Table V, same states:
    /// A1 −14..−18% iterations, humanoid −5..−9%). A step that fails every attempt with these
    /// shortcuts is taken once more without them (`step::step_with`).
    pub drop_redundant_friction: bool,
    /// A step whose every attempt with the exact (second-order) friction cones fails is taken
    /// with each cone replaced by the four-sided pyramid inscribed in it (the `linear` contact
    /// model, Dojo's LCP form), and the whole step is solved again with the exact cones
    /// warm-started from the pyramid's impulses (a failed pyramid's last iterate's too); the
    /// step is exact when that converges. When it does not (and the
    /// start rebuilt from its minimal coordinates fails too), the pyramid's step is returned as
    /// [`crate::SolveStatus::PyramidFriction`]: no penetration, every contact force inside its
    /// Coulomb cone, but a sliding contact's friction along the pyramid's nearest edge instead
    /// of against the slip, and no gradients. Default true; false reports such a step as
    /// failed. Why: the shared humanoid with its legs crossed and a foot sliding
    /// (`step_bench humanoid.xml 1000 1 155`, step 188) jams the exact cones from the previous
    /// step's impulses on every attempt (~3100 iterations, then unconverged); the pyramid
    /// converges in ~20 iterations and the exact cones from its impulses in ~10 (seed 21's
    /// step 591 jams the pyramid too, and converges from its last iterate's impulses).
    pub pyramid_fallback: bool,
    /// The central-path target never goes below `kappa_tol / undercut` (Dojo's undercut). Default 10.
    pub undercut: f64,
    /// Start contact and limit variables from the previous step's solution (pushed
    /// `warm_start_margin` inside their cones) instead of the neutral point. Default true: a
    /// box sliding at 30° to the axes needs 1.6 iterations per step warm and 12.7 cold, and the
    /// cold start stalled on 2 of 400 steps (BENCHMARKS.md).
    pub warm_start: bool,
    /// Margin inside the cones for warm-started variables. Default 1e-6.
    pub warm_start_margin: f64,
    /// How far inside their cones a warm start's impulses (γ, ξ) are pushed when its first
    /// predictor step is cut below half its length (contacts changing state). Default 1e-2
    /// (1e-3 until session 29: 6-10% more iterations on the humanoid and A1). A first attempt
    /// so widened that fails is retried widened by 1e-3 before anything else.
    pub warm_start_widening: f64,
    /// The same widening relative to the impulse the moving bodies' weight delivers in a step,
    /// `Σ m g h` (`Model::weight_impulse`): a warm start is widened by the larger of the two.
    /// Default 0.1 (the shared humanoid: 0.40 N·s; a 1 kg box: 0.0098 N·s, below the absolute
    /// 1e-2); 0 leaves the absolute widening alone (BENCHMARKS.md, session 31: −5..−9% iterations
    /// on the robots, +1.7% on the random stress scenes).
    pub warm_start_widening_weight: f64,
    /// Fraction-to-boundary floor for orthant variables, τ_min. Default 0.95.
    pub tau_min: f64,
    /// Fraction-to-boundary ceiling for second-order cones, τ_max. Default 0.99.
    pub tau_max: f64,
    /// Proximal regularisation of the friction impulses (of the second-order friction cones;
    /// the pyramid model's rows are unchanged) in the interior-point Newton matrix, relative to
    /// the mean complementarity `μ` of the iterate: the slip rows of the matrix
    /// become `Δη₂:₃ - J_t Δv - ρ Δξ₂:₃` with `ρ = friction_proximal · μ`, while the residual
    /// stays exact, so a converged solution is the same and `ρ` vanishes as the solve
    /// converges; only the directions change. Default 0.01; 0 turns it off. Why: the shared
    /// Panda with its fingertip pads pressed into the floor by ~900 N (`option_ab panda.xml
    /// 1000 10`, step 452) failed every tier and sub-step, and its last resort's all-active
    /// attempts (835 candidates) took 8.4 s; with it, 1.1 s on the same state. (Central-path
    /// solves, whose matrix is the gradients', take none.)
    pub friction_proximal: f64,
    /// Regularisation `ε` on constraint pivots, `-ε I`: keeps redundant constraints of closed
    /// loops (a planar four-bar in 3-D) solvable without changing the solution. Default 1e-12.
    pub regularization: f64,
    /// Contact activation margin (m). Each step, a candidate whose current signed distance
    /// exceeds `activation_margin + h (2 u + h |g|)`, with `u` the rate at which its two witness
    /// points approach along the contact normal at the current velocities (a failed solve
    /// retries with `u` a bound on the speed of any point of one geom relative to the other's
    /// body, `|v| + |ω| ρ`, `ρ` the geom's reach), takes no part in the solve: zero impulse, no
    /// interior-point variables, no factorisation work. After the solve, every inactive candidate
    /// is checked at the new configuration and the step is solved again with it active if its
    /// distance fell below `activation_margin / 4`, so no contact the step makes is missed.
    /// A solve that fails with candidates left out is solved again with all of them active.
    /// A pair with a geom smaller than the margin uses that geom's bounding radius instead
    /// (the smaller geom's; `solver::activation::candidate_margin`: fingertip pads are not
    /// activated at several times their own size). Between two bodies that can only slide
    /// along one axis relative to each other, every slide on the way limited (a parallel
    /// gripper's fingers), `2 h u` is at most the travel the limits leave in the direction they
    /// move (`solver::activation::slide_room`). Of a box's corners against a plane or
    /// another box, those more than half the margin (plus twice the step's travel at the
    /// difference of their approach rates) above the lowest corner are left out too
    /// (`solver::activation::LOWEST_OF`): the lowest touches first.
    /// Default 0.01 m; `f64::INFINITY` keeps every candidate active. Measured 2026-11-23
    /// (all-active → 0.01): 1000 random stress scenes 74 → 69 failing in half the time, the
    /// 14-sphere pyramid 19/500 unconverged steps → 0, every `cargo test` and pytest case as
    /// before. (It became the default once box corners on a box were measured against the
    /// pair's contact face: before, a 1000 kg box on a 1 kg box sank into it and its corners
    /// flickered in and out of the active set, stalling the solve.)
    ///
    /// Joint and tendon limits are activated likewise: a joint's limits take part when a
    /// limited coordinate is within `max(activation_margin, 0.1) + 4 h |θ̇|` (rad or m) of a
    /// bound at the step's start (a tendon limit: its length, with the rate bound
    /// `Σ |coef q̇|`), and the step is solved again if it brought an inactive one within
    /// `activation_margin / 4` of a bound. `f64::INFINITY` keeps every limit active too.
    pub activation_margin: f64,
    /// Central-path parameter at which gradients are taken (`None`: the exact derivative at the
    /// simulated solution). The step itself is always solved to `kappa_tol`; see
    /// [`crate::gradients`]. Default `None`.
    pub kappa_grad: Option<f64>,
    /// Nesterov–Todd scaling of the friction cones' Newton rows (see
    /// [`crate::contact::cone::NtScaling`]). Default true; false gives Dojo's unscaled
    /// linearisation of `ξ ∘ η = κe` (kept for comparison).
    pub nt_scaling: bool,
    /// Start the central-path solve of `kappa_grad` from the step's hard solution with every
    /// complementarity pair moved to product κ (falling back to the neutral start when that
    /// solve fails). Default true; false starts from the neutral point directly (the former
    /// behaviour, kept for comparison).
    pub central_warm_start: bool,
    /// Hold every contact candidate and limit of the model at `b ∘ c = κ` in the smoothed step
    /// of `kappa_grad`, however far from touching (the relaxed problem of the Dojo paper, which
    /// has no activation), instead of the candidates within reach at a κ tapered with their
    /// distance (`solver::taper`) and the limits the step activated. Default false. True gives
    /// candidates out of reach a gradient (each pushes with `κ / gap`), which contact-implicit
    /// planning may want, at a cost: on the shared robots a gradient at κ then took 6-27× the
    /// exact one, and the Panda's smoothed velocities moved 2.6 rad/s at κ = 3e-4 (0.31 with
    /// the activated candidates alone; `examples/benchmarks/smoothing_bias.py`).
    pub smooth_every_candidate: bool,
    /// A step whose solve fails is taken again as 2, then 4, … up to this many equal
    /// sub-steps of `h / n` from the same state (each solved like a step; the control and
    /// applied forces held), and reported with [`crate::StepReport::subdivisions`]. 1 turns
    /// it off. Default 32. Why: the solves that still fail are stiff at `h` (a spinning chain at
    /// `h |ω|` ≈ 0.1–0.3 whose smooth Newton matrix turns singular, a first impact of many
    /// contacts); at `h / 2` most converge (measured on the 74 failing random stress scenes).
    /// One step of the 10⁵-step random-control hopper needs 16 (`tests/stress` measure).
    /// Gradients through a subdivided step chain the sub-steps' linearisations
    /// (`gradients/substeps.rs`).
    pub max_subdivisions: u32,
    /// Largest fraction of the kinetic energy that constraint impulses (joints, contacts,
    /// limits) may add in one step before the step is taken again as sub-steps
    /// (`max_subdivisions`; the step is kept if no subdivision passes). 0 turns the guard off.
    /// Default 0.05. Why: constraint impulses do no work up to O(h) terms, and contacts only
    /// dissipate, but the implicit step can have a second, energy-gaining root that the solve
    /// sometimes finds (measured: random stress scene 553 gained 5.4 J, 76% of its energy, at one
    /// impact, and scene 709 2.4 J; at h/2 both lose energy). The allowance is
    /// `energy_guard (T + T⁺) + Σ m |g|² h²` (`mechanics::constraint_work`); on the Table V robots
    /// the constraint work of every step was negative.
    pub energy_guard: f64,
    /// Largest rotation (rad) a body may turn in one step, `h |ω|` at the step's midpoint
    /// angular velocity: a converged step that turns a body further is taken again as the
    /// fewest sub-steps (a power of two, ≤ `max_subdivisions`) that keep every sub-step within
    /// it. `f64::INFINITY` turns it off. Default 0.3 (17°). Why: the variational integrator's
    /// energy error grows with the rotation per step; a chain whose link whips past 40-80 rad/s
    /// at h = 0.01 gained 6-9% of its energy in 300 steps (random stress scenes 34 and 716),
    /// 0.3-3.4% when held to 0.3 rad (`crate::step::rotation_substeps`).
    pub max_step_rotation: f64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            timestep: 0.01,
            gravity: Vector3::new(0.0, 0.0, -9.81),
            rtol: 1e-10,
            max_iter: 50,
            endgame_iter: 150,
            max_ls: 10,
            regularization: 1e-12,
            friction_proximal: 0.01,
            warm_start_widening_weight: 0.1,
            kappa_tol: 1e-11,
            acceptable_rtol: 1e-8,
            acceptable_kappa_tol: 1e-8,
            acceptable_iter: 15,
            stall_iter: 20,
            cone_gap: true,
            drop_redundant_friction: true,
            pyramid_fallback: true,
            undercut: 10.0,
            warm_start: true,
            warm_start_margin: 1e-6,
            warm_start_widening: 1e-2,
            tau_min: 0.95,
            tau_max: 0.99,
            activation_margin: 0.01,
            kappa_grad: None,
            nt_scaling: true,
            central_warm_start: true,
            smooth_every_candidate: false,
            max_subdivisions: 32,
            energy_guard: 0.05,
            max_step_rotation: 0.3,
        }
    }
}

impl Options {
    /// Check every field; errors name the field and value.
    pub fn validate(&self) -> crate::Result<()> {
        use crate::{Error, ensure};
        ensure!(
            self.timestep.is_finite() && self.timestep > 0.0,
            Error::model("timestep", self.timestep, "must be finite and > 0")
        );
        ensure!(
            self.gravity.iter().all(|g| g.is_finite()),
            Error::model("gravity", self.gravity.as_slice(), "must be finite")
        );
        ensure!(
            self.rtol.is_finite() && self.rtol > 0.0,
            Error::model("rtol", self.rtol, "must be finite and > 0")
        );
        for (name, tol) in [
            ("kappa_tol", self.kappa_tol),
            ("acceptable_rtol", self.acceptable_rtol),
            ("acceptable_kappa_tol", self.acceptable_kappa_tol),
        ] {
            ensure!(
                tol.is_finite() && tol >= 0.0,
                Error::model(name, tol, "must be finite and >= 0")
            );
        }
        ensure!(
            self.max_iter >= 1,
            Error::model("max_iter", self.max_iter, "must be >= 1")
        );
        ensure!(
            self.regularization.is_finite() && self.regularization >= 0.0,
            Error::model(
                "regularization",
                self.regularization,
                "must be finite and >= 0"
            )
        );
        ensure!(
            self.friction_proximal.is_finite() && self.friction_proximal >= 0.0,
            Error::model(
                "friction_proximal",
                self.friction_proximal,
                "must be finite and >= 0"
            )
        );
        ensure!(
            self.warm_start_widening_weight.is_finite() && self.warm_start_widening_weight >= 0.0,
            Error::model(
                "warm_start_widening_weight",
                self.warm_start_widening_weight,
                "must be finite and >= 0"
            )
        );
        ensure!(
            self.warm_start_margin.is_finite() && self.warm_start_margin > 0.0,
            Error::model(
                "warm_start_margin",
                self.warm_start_margin,
                "must be finite and > 0"
            )
        );
        ensure!(
            self.warm_start_widening.is_finite() && self.warm_start_widening > 0.0,
            Error::model(
                "warm_start_widening",
                self.warm_start_widening,
                "must be finite and > 0"
            )
        );
        ensure!(
            self.activation_margin > 0.0,
            Error::model(
                "activation_margin",
                self.activation_margin,
                "must be > 0 (f64::INFINITY keeps every contact active)"
            )
        );
        ensure!(
            self.energy_guard.is_finite() && self.energy_guard >= 0.0,
            Error::model(
                "energy_guard",
                self.energy_guard,
                "must be finite and >= 0 (0 turns the guard off)"
            )
        );
        ensure!(
            self.max_step_rotation > 0.0,
            Error::model(
                "max_step_rotation",
                self.max_step_rotation,
                "must be > 0 rad (f64::INFINITY turns the limit off)"
            )
        );
        ensure!(
            (1..=1024).contains(&self.max_subdivisions),
            Error::model(
                "max_subdivisions",
                self.max_subdivisions,
                "must be in 1..=1024 (1 turns subdivision off)"
            )
        );
        if let Some(k) = self.kappa_grad {
            ensure!(
                k.is_finite() && k > 0.0,
                Error::model("kappa_grad", k, "must be finite and > 0 (or None)")
            );
        }
        Ok(())
    }
}
