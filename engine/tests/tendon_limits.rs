//! Fixed-tendon limits as inequality constraints: a two-hinge arm driven into the limit of
//! `L = ½ q₁ - ½ q₂` holds it, carries the analytic impulse, and releases when pushed away.
use ukemi_engine::model::TendonLimitSpec;
use ukemi_engine::{
    ActuatorSpec, BodySpec, JointKind, JointSpec, Model, ModelBuilder, SolveStatus, State,
    Workspace, qpos, qvel, set_minimal, step,
};

const COEF: [f64; 2] = [0.5, -0.5];
const RANGE: (f64, f64) = (-0.3, 0.4);

/// A horizontal two-link arm (hinges about z, gravity along -z loads only the joint
/// constraints), damped, one motor per hinge, with the tendon limit `RANGE` on
/// `COEF · (q₁, q₂)` when `limited`.
fn arm(limited: bool) -> Model {
    let link = |name: &str, x: f64| BodySpec::new(name, 1.0, [0.01, 0.09, 0.09]).pos([x, 0.0, 0.0]);
    let hinge = |name: &str, parent: &str, child: &str, pa: [f64; 3]| {
        JointSpec::new(name, JointKind::Revolute, parent, child)
            .axis([0.0, 0.0, 1.0])
            .anchors(pa, [-0.5, 0.0, 0.0])
            .damping(8.0)
    };
    let mut b = ModelBuilder::new()
        .timestep(0.01)
        .body(link("l1", 0.5))
        .body(link("l2", 1.5))
        .joint(hinge("j1", "world", "l1", [0.0; 3]))
        .joint(hinge("j2", "l1", "l2", [0.5, 0.0, 0.0]))
        .actuator(ActuatorSpec::motor("m1", "j1", 0, 1.0))
        .actuator(ActuatorSpec::motor("m2", "j2", 0, 1.0));
    if limited {
        b.add_tendon_limit(TendonLimitSpec {
            name: "hamstring".into(),
            terms: vec![("j1".into(), 0, COEF[0]), ("j2".into(), 0, COEF[1])],
            range: RANGE,
        });
    }
    b.compile().unwrap()
}

fn length(model: &Model, state: &State) -> f64 {
    let q = qpos(model, state);
    COEF[0] * q[0] + COEF[1] * q[1]
}

#[test]
fn tendon_limit_holds_carries_the_holding_torque_and_releases() {
    let model = arm(true);
    let counts = model.variable_counts();
    assert!(counts.contains(&("tendon_limit", 4)), "{counts:?}");
    assert_eq!(counts[2], ("joint_limit", 0));
    let h = model.timestep();
    let mut state = State::reference(&model);
    let mut ws = Workspace::new(&model);
    // generalized force -F·coef: pushes L down (power -F L̇), and at rest on L = lo is
    // balanced by the tendon force coef_i γ/h exactly when γ/h = F
    let force = 4.0;
    let ctrl = [-force * COEF[0], -force * COEF[1]];
    let (mut worst, mut max_it) = (f64::MIN, 0);
    for _ in 0..800 {
        let r = step(&model, &mut state, &mut ws, &ctrl).unwrap();
        assert_eq!(r.status, SolveStatus::Converged, "{r:?}");
        max_it = max_it.max(r.iterations);
        worst = worst.max(RANGE.0 - length(&model, &state));
    }
    let (len, qd) = (length(&model, &state), qvel(&model, &state));
    let held = state.tendon_impulse(&model)[0] / h;
    eprintln!(
        "held: L - lo = {:.3e}, worst violation {worst:.3e}, |qvel| {:.2e}, γ/h = {held:.12} \
         (analytic {force}), max iterations {max_it}",
        len - RANGE.0,
        qd[0].abs().max(qd[1].abs())
    );
    assert!(worst < 1e-8, "tendon limit violated by {worst:.3e}");
    assert!(
        (len - RANGE.0).abs() < 1e-8,
        "should rest on the limit: L = {len}"
    );
    assert!(qd.iter().all(|v| v.abs() < 1e-6), "not at rest: {qd:?}");
    assert!(
        (held - force).abs() < 1e-6 * force,
        "tendon force {held} vs analytic {force}"
    );
    assert!(max_it <= 30);
    // push the other way: it leaves the lower limit and the impulse vanishes
    let away = [force * COEF[0], force * COEF[1]];
    for _ in 0..50 {
        let r = step(&model, &mut state, &mut ws, &away).unwrap();
        assert_eq!(r.status, SolveStatus::Converged, "{r:?}");
    }
    let len = length(&model, &state);
    let imp = state.tendon_impulse(&model)[0];
    eprintln!(
        "released: L - lo = {:.3e}, impulse {imp:.2e}",
        len - RANGE.0
    );
    assert!(len > RANGE.0 + 0.05, "still at the limit: L = {len}");
    assert!(imp.abs() < 1e-9, "released tendon still pushes: {imp:e}");
}

#[test]
fn upper_tendon_limit_holds_with_a_negative_impulse() {
    let model = arm(true);
    let h = model.timestep();
    let mut state = State::reference(&model);
    set_minimal(&model, &mut state, &[0.2, -0.2], &[0.0, 0.0]).unwrap();
    let mut ws = Workspace::new(&model);
    let force = 2.0;
    let ctrl = [force * COEF[0], force * COEF[1]];
    let mut worst = f64::MIN;
    for _ in 0..800 {
        let r = step(&model, &mut state, &mut ws, &ctrl).unwrap();
        assert_eq!(r.status, SolveStatus::Converged, "{r:?}");
        worst = worst.max(length(&model, &state) - RANGE.1);
    }
    let held = state.tendon_impulse(&model)[0] / h;
    eprintln!("upper: worst violation {worst:.3e}, γ/h = {held:.12}");
    assert!(worst < 1e-8, "upper limit violated by {worst:.3e}");
    assert!((length(&model, &state) - RANGE.1).abs() < 1e-8);
    assert!((held + force).abs() < 1e-6 * force, "{held} vs -{force}");
}

#[test]
fn inside_the_range_the_limited_arm_moves_as_the_free_one() {
    let (free, limited) = (arm(false), arm(true));
    // no inequality variables without a tendon limit: plain Newton
    assert!(free.variable_counts().contains(&("tendon_limit", 0)));
    assert!(State::reference(&free).ineq_vars.is_empty());
    let (mut a, mut b) = (State::reference(&free), State::reference(&limited));
    let (mut wa, mut wb) = (Workspace::new(&free), Workspace::new(&limited));
    let (mut worst, mut inactive) = (0.0f64, 0);
    for k in 0..200 {
        let u = [0.3 * (0.05 * k as f64).sin(), -0.2];
        step(&free, &mut a, &mut wa, &u).unwrap();
        step(&limited, &mut b, &mut wb, &u).unwrap();
        // far from its bounds the limit takes no part in the step (`activation_margin`)
        inactive += usize::from(!wb.tendon_active()[0]);
        let l = length(&limited, &b);
        assert!(
            l > RANGE.0 + 0.05 && l < RANGE.1 - 0.05,
            "reached the range: {l}"
        );
        let (qa, qb) = (qpos(&free, &a), qpos(&limited, &b));
        worst = worst.max((qa[0] - qb[0]).abs().max((qa[1] - qb[1]).abs()));
    }
    eprintln!(
        "free vs limited inside the range: max |Δq| {worst:.2e}, {inactive} of 200 steps without the limit"
    );
    // an active limit's impulse far from its bounds is the complementarity floor κ/s ~ 1e-12
    assert!(worst < 1e-9, "{worst:e}");
    assert!(inactive > 0);
}

#[test]
fn bad_tendon_limits_are_errors_naming_the_field() {
    let bad = |terms: Vec<(&str, usize, f64)>, range: (f64, f64)| {
        let mut b = ModelBuilder::new()
            .body(BodySpec::new("l1", 1.0, [0.1; 3]))
            .joint(JointSpec::new("j1", JointKind::Revolute, "world", "l1"))
            .body(BodySpec::new("l2", 1.0, [0.1; 3]))
            .joint(JointSpec::new("j2", JointKind::Spherical, "l1", "l2"));
        b.add_tendon_limit(TendonLimitSpec {
            name: "t".into(),
            terms: terms
                .into_iter()
                .map(|(j, d, c)| (j.to_string(), d, c))
                .collect(),
            range,
        });
        b.compile().unwrap_err().to_string()
    };
    let e = bad(vec![("j1", 0, 1.0)], (0.5, 0.5));
    assert!(e.contains("tendon_limit[t].range"), "{e}");
    let e = bad(vec![("j1", 0, f64::NAN)], (0.0, 1.0));
    assert!(e.contains("coef"), "{e}");
    let e = bad(vec![("nope", 0, 1.0)], (0.0, 1.0));
    assert!(e.contains("unknown joint"), "{e}");
    let e = bad(vec![("j2", 0, 1.0)], (0.0, 1.0));
    assert!(e.contains("hinge or slide"), "{e}");
    let e = bad(vec![("j1", 0, 0.0)], (0.0, 1.0));
    assert!(e.contains("non-zero coef"), "{e}");
}

#[test]
fn mjcf_limited_fixed_tendons_are_enforced_without_warnings() {
    let xml = r#"<mujoco>
  <worldbody>
    <body name="a"><joint name="h1" type="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.05" contype="0" conaffinity="0"/>
      <body name="b" pos="0 0 -0.5"><joint name="h2" type="hinge" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.05" contype="0" conaffinity="0"/>
      </body>
    </body>
  </worldbody>
  <tendon>
    <fixed name="t" limited="true" range="-0.3 2">
      <joint joint="h1" coef=".5"/><joint joint="h2" coef="-.5"/>
    </fixed>
    <fixed name="free"><joint joint="h1" coef="1"/></fixed>
  </tendon>
</mujoco>"#;
    let m = ukemi_engine::mjcf::load_str(xml, "t.xml").unwrap();
    assert!(m.warnings.is_empty(), "{:?}", m.warnings);
    assert_eq!(m.model.tendon_limits.len(), 1);
    assert_eq!(m.model.tendon_limits[0].range, (-0.3, 2.0));
    let bad = xml.replace("range=\"-0.3 2\"", "range=\"2 -0.3\"");
    let e = ukemi_engine::mjcf::load_str(&bad, "t.xml")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("t.xml:11") && e.contains("`range` = \"2 -0.3\""),
        "{e}"
    );
}
