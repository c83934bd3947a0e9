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
