//! Minimal ↔ maximal coordinates: exact round trips for every joint kind, and random
//! mechanisms that compile and step without panics.
mod common;
use common::*;
use nalgebra::{UnitQuaternion, Vector3};
use proptest::prelude::*;
use ukemi_engine::{
    BodySpec, JointKind, JointSpec, Model, ModelBuilder, State, Workspace, qpos, qvel, set_minimal,
    step,
};

/// world --floating--> base --kind--> tip, with a tilted axis, offset anchors and a rotated tip.
fn two_body(kind: JointKind) -> Model {
    let tip_quat = UnitQuaternion::from_euler_angles(0.4, -0.2, 0.9);
    let q = tip_quat.quaternion();
    let base_anchor = Vector3::new(0.1, -0.2, 0.3);
    let tip_pos = Vector3::new(0.5, 0.4, 1.0);
    let tip_anchor = tip_quat.inverse() * (Vector3::new(0.0, 0.0, 1.0) + base_anchor - tip_pos);
    ModelBuilder::new()
        .body(
            BodySpec::new("base", 2.0, [0.2, 0.3, 0.4])
                .pos([0.0, 0.0, 1.0])
                .com([0.05, 0.0, -0.02]),
        )
        .body(
            BodySpec::new("tip", 1.0, [0.1, 0.15, 0.2])
                .pos(tip_pos.into())
                .quat([q.w, q.i, q.j, q.k]),
        )
        .joint(JointSpec::new("root", JointKind::Floating, "world", "base"))
        .joint(
            JointSpec::new("j", kind, "base", "tip")
                .axis([0.3, -0.5, 0.8])
                .anchors(base_anchor.into(), tip_anchor.into()),
        )
        .compile()
        .unwrap()
}

fn random_coords(model: &Model, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut x = seed as f64;
    let mut rnd = || {
        x = (x * 12.9898 + 78.233).sin() * 43758.5453;
        x.fract()
    };
    let mut q = Vec::new();
    for j in &model.joints {
        for _ in 0..j.ntrans {
            q.push(rnd());
        }
        match j.rot.nq() {
            4 => {
                let v: Vec<f64> = (0..4).map(|_| rnd()).collect();
                let n = v.iter().map(|a| a * a).sum::<f64>().sqrt();
                q.extend(v.iter().map(|a| a / n));
            }
            k => q.extend((0..k).map(|_| 3.0 * rnd())),
        }
    }
    let v = (0..model.nv).map(|_| 2.0 * rnd()).collect();
    (q, v)
}

#[test]
fn round_trip_is_exact_for_every_joint_kind() {
    for kind in JointKind::ALL {
        let model = two_body(kind);
        for seed in 1..20 {
            let (q, v) = random_coords(&model, seed);
            let mut state = State::reference(&model);
            set_minimal(&model, &mut state, &q, &v).unwrap();
            let (q2, v2) = (qpos(&model, &state), qvel(&model, &state));
            let eq = q
                .iter()
                .zip(&q2)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            let ev = v
                .iter()
                .zip(&v2)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(
                eq < 1e-12 && ev < 1e-12,
                "{kind:?} seed {seed}: qpos error {eq:.2e}, qvel error {ev:.2e}"
            );
            assert!(
                constraint_violation(&model, &state) < 1e-12,
                "{kind:?}: FK breaks a constraint"
            );
        }
    }
}

#[test]
fn reference_pose_gives_qpos0_and_mujoco_free_joint_layout() {
    let model = two_body(JointKind::Revolute);
    // free joint: body frame origin and orientation; hinge at 0
    assert_eq!(model.nq, 8);
    let q0 = &model.qpos0;
    assert!(
        q0[0].abs() < 1e-12 && (q0[2] - 1.0).abs() < 1e-12 && (q0[3] - 1.0).abs() < 1e-12,
        "{q0:?}"
    );
    assert!(q0[7].abs() < 1e-12);
}

#[derive(Debug, Clone)]
struct RandomBody {
    parent: usize,
    kind: usize,
    moments: [f64; 3],
    pos: [f64; 3],
    euler: [f64; 3],
    anchor: [f64; 3],
    damping: f64,
    stiffness: f64,
}

fn random_body(i: usize) -> impl Strategy<Value = RandomBody> {
    let m = 0.1f64..2.0;
    (
        0..=i,
        0..16usize,
        (m.clone(), m.clone(), m),
        prop::array::uniform3(-1.0f64..1.0),
        prop::array::uniform3(-3.0f64..3.0),
        prop::array::uniform3(-0.5f64..0.5),
        0.0f64..1.0,
        0.0f64..5.0,
    )
        .prop_map(
            |(parent, kind, (a, b, c), pos, euler, anchor, damping, stiffness)| {
                // sort so the triangle inequality holds: largest <= sum of the others
                let mut m = [a, b, c];
                m.sort_by(|x, y| x.total_cmp(y));
                m[2] = m[2].min(m[0] + m[1]);
                RandomBody {
                    parent,
                    kind,
                    moments: m,
                    pos,
                    euler,
                    anchor,
                    damping,
                    stiffness,
                }
            },
        )
}

fn build(bodies: &[RandomBody]) -> Model {
    let mut b = ModelBuilder::new().timestep(0.01);
    let mut poses: Vec<(Vector3<f64>, UnitQuaternion<f64>)> =
        vec![(Vector3::zeros(), UnitQuaternion::identity())];
    for (i, rb) in bodies.iter().enumerate() {
        let parent = rb.parent.min(i);
        let q = UnitQuaternion::from_euler_angles(rb.euler[0], rb.euler[1], rb.euler[2]);
        let p = Vector3::from(rb.pos) + poses[parent].0;
        let (pp, pq) = poses[parent];
        let world_anchor = pp + pq * Vector3::from(rb.anchor);
        let child_anchor = q.inverse() * (world_anchor - p);
        let name = format!("b{}", i + 1);
        let pname = if parent == 0 {
            "world".to_string()
        } else {
            format!("b{parent}")
        };
        let qq = q.quaternion();
        b = b.body(
            BodySpec::new(&name, 1.0, rb.moments)
                .pos(p.into())
                .quat([qq.w, qq.i, qq.j, qq.k]),
        );
        b = b.joint(
            JointSpec::new(
                &format!("j{}", i + 1),
                JointKind::ALL[rb.kind],
                &pname,
                &name,
            )
            .axis([rb.euler[2], 1.0, rb.euler[0]])
            .anchors(rb.anchor, child_anchor.into())
            .damping(rb.damping)
            .stiffness(rb.stiffness),
        );
        poses.push((p, q));
    }
    b.compile().unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn random_mechanisms_compile_round_trip_and_step(bodies in (1usize..7).prop_flat_map(|n| (0..n).map(random_body).collect::<Vec<_>>())) {
        let model = build(&bodies);
        let mut state = State::reference(&model);
        let (q, v) = (qpos(&model, &state), qvel(&model, &state));
        let mut again = State::reference(&model);
        set_minimal(&model, &mut again, &q, &v).unwrap();
        for (a, b) in state.com_pos.iter().zip(&again.com_pos) {
            prop_assert!((a - b).abs() < 1e-9);
        }
        let mut ws = Workspace::new(&model);
        for _ in 0..20 {
            let r = step(&model, &mut state, &mut ws, &[]).unwrap();
            prop_assert_eq!(r.status, ukemi_engine::SolveStatus::Converged, "{:?}", r);
            prop_assert!(state.com_pos.iter().all(|x| x.is_finite()));
        }
        prop_assert!(constraint_violation(&model, &state) < 1e-8);
    }
}
