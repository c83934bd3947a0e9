//! Compile-time validation: every bad field is rejected with a message naming it and its value.
use nalgebra::Matrix3;
use ukemi_engine::{BodySpec, JointKind, JointSpec, ModelBuilder};

fn good() -> ModelBuilder {
    ModelBuilder::new()
        .body(BodySpec::new("a", 1.0, [0.1, 0.1, 0.1]).pos([0.0, 0.0, -1.0]))
        .joint(
            JointSpec::new("hinge", JointKind::Revolute, "world", "a")
                .anchors([0.0; 3], [0.0, 0.0, 1.0]),
        )
}

fn expect_err(b: ModelBuilder, needles: &[&str]) {
    let msg = b
        .compile()
        .map(|_| ())
        .expect_err("should fail")
        .to_string();
    for n in needles {
        assert!(msg.contains(n), "message {msg:?} lacks {n:?}");
    }
}

#[test]
fn good_model_compiles() {
    assert!(good().compile().is_ok());
}

#[test]
fn bad_mass_inertia_quaternion_are_named() {
    expect_err(
        good().body(BodySpec::new("b", -2.0, [0.1; 3])),
        &["body[b].mass", "-2.0"],
    );
    expect_err(
        good().body(BodySpec::new("b", f64::NAN, [0.1; 3])),
        &["body[b].mass", "NaN"],
    );
    let asym = Matrix3::new(1.0, 0.2, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
    expect_err(
        good().body(BodySpec::new("b", 1.0, [1.0; 3]).inertia_matrix(asym)),
        &["body[b].inertia", "symmetric"],
    );
    expect_err(
        good().body(BodySpec::new("b", 1.0, [1.0, -1.0, 1.0])),
        &["body[b].inertia", "positive definite"],
    );
    expect_err(
        good().body(BodySpec::new("b", 1.0, [1.0, 1.0, 5.0])),
        &["body[b].inertia", "triangle"],
    );
    expect_err(
        good().body(BodySpec::new("b", 1.0, [0.1; 3]).quat([1.0, 1.0, 0.0, 0.0])),
        &["body[b].quat", "unit"],
    );
    expect_err(
        good().body(BodySpec::new("b", 1.0, [0.1; 3]).quat([f64::INFINITY, 0.0, 0.0, 0.0])),
        &["body[b].quat", "finite"],
    );
}

#[test]
fn bad_joints_are_named() {
    let b = ModelBuilder::new().body(BodySpec::new("a", 1.0, [0.1; 3]));
    expect_err(
        b.clone()
            .joint(JointSpec::new("j", JointKind::Revolute, "ground", "a")),
        &["joint[j].parent", "ground", "unknown"],
    );
    expect_err(
        b.clone()
            .joint(JointSpec::new("j", JointKind::Revolute, "world", "a").axis([0.0; 3])),
        &["joint[j].axis", "non-zero"],
    );
    expect_err(b.clone(), &["body[a]", "no joint"]);
    expect_err(
        good().joint(JointSpec::new("hinge", JointKind::Fixed, "world", "a")),
        &["joint[hinge].name", "duplicate"],
    );
    expect_err(
        good().body(BodySpec::new("a", 1.0, [0.1; 3])),
        &["body[a].name", "duplicate"],
    );
    expect_err(
        b.clone().joint(
            JointSpec::new("j", JointKind::Revolute, "world", "a")
                .anchors([0.0, 0.0, 1.0], [0.0; 3]),
        ),
        &["joint[j].anchors", "constraint violated"],
    );
    expect_err(
        b.clone()
            .joint(JointSpec::new("j", JointKind::Revolute, "world", "a").damping(-1.0)),
        &["joint[j].damping", "-1.0"],
    );
}

#[test]
fn undeclared_cycle_is_rejected_and_loop_flag_accepts_it() {
    let two = ModelBuilder::new()
        .body(BodySpec::new("a", 1.0, [0.1; 3]))
        .body(BodySpec::new("b", 1.0, [0.1; 3]))
        .joint(JointSpec::new("ab", JointKind::Spherical, "a", "b"))
        .joint(JointSpec::new("ba", JointKind::Spherical, "b", "a"));
    expect_err(two.clone(), &["cycle", "loop"]);
    let double_parent = good().joint(
        JointSpec::new("second", JointKind::Spherical, "world", "a")
            .anchors([0.0; 3], [0.0, 0.0, 1.0]),
    );
    expect_err(
        double_parent.clone(),
        &["joint[second].child", "already the child", "loop"],
    );
    let closed = good().joint(
        JointSpec::new("second", JointKind::Spherical, "world", "a")
            .anchors([0.0; 3], [0.0, 0.0, 1.0])
            .closing_loop(),
    );
    assert!(closed.compile().is_ok());
}

#[test]
fn bad_options_are_named() {
    expect_err(good().timestep(0.0), &["timestep", "0.0"]);
    expect_err(good().gravity([0.0, f64::NAN, 0.0]), &["gravity"]);
}

#[test]
fn bad_frictionloss_and_contact_pairs_are_named() {
    use ukemi_engine::{ContactModel, GeomSpec, PairSpec, Shape};
    let mut b = good();
    b.add_joint(JointSpec::new("slider", JointKind::Prismatic, "a", "b").frictionloss(-0.5));
    expect_err(
        b.body(BodySpec::new("b", 1.0, [0.1; 3])),
        &["joint[slider].frictionloss", "-0.5", ">= 0"],
    );
    let geoms = || {
        good()
            .geom(GeomSpec::new("floor", "world", Shape::Plane))
            .geom(GeomSpec::new("ball", "a", Shape::Sphere { radius: 0.1 }))
            .geom(GeomSpec::new("cap", "a", Shape::Sphere { radius: 0.05 }))
    };
    let pair = |a: &str, b: &str, friction: f64| PairSpec {
        geom_a: a.into(),
        geom_b: b.into(),
        friction,
        model: ContactModel::Nonlinear,
    };
    let mut b = geoms();
    b.add_pair(pair("floor", "nothing", 0.5));
    expect_err(b, &["pair[0].geom_b", "nothing", "unknown geom"]);
    let mut b = geoms();
    b.add_pair(pair("floor", "ball", -1.0));
    expect_err(b, &["pair[0].friction", "-1.0"]);
    let mut b = geoms();
    b.add_pair(pair("ball", "cap", 0.5));
    expect_err(
        b,
        &["pair[0].geom_b", "cap", "on the body of geom \"ball\""],
    );
    // an explicit pair replaces the pair of the rules: one set of candidates, its friction
    let mut b = geoms();
    b.add_pair(pair("ball", "floor", 0.2));
    let m = b.compile().unwrap();
    let plain = geoms().compile().unwrap();
    assert_eq!(m.contacts.len(), plain.contacts.len());
    for c in &m.contacts {
        let named = |n: &str| m.geoms[c.geom_a].name == n || m.geoms[c.geom_b].name == n;
        assert_eq!(c.friction, if named("ball") { 0.2 } else { 0.5 });
    }
}
