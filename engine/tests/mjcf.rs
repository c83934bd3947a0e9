//! MJCF loader edge cases: defaults and classes, orientations, composite joints with MuJoCo's
//! dof order and `ref`, inertia from geoms, errors with element and line.
use ukemi_engine::mjcf::load_str;
use ukemi_engine::{Error, State, qpos, qvel, set_minimal};

fn load(xml: &str) -> ukemi_engine::mjcf::MjcfModel {
    load_str(xml, "<test>").unwrap()
}

#[test]
fn default_classes_and_childclass_are_inherited() {
    let m = load(
        r#"<mujoco>
        <default><joint damping="2"/>
          <default class="arm"><joint damping="5" armature="0.1"/>
            <default class="hand"><joint stiffness="3"/></default></default></default>
        <worldbody><body name="a" childclass="arm"><joint name="j1"/><geom size="0.1"/>
          <body name="b"><joint name="j2" class="hand"/><geom size="0.1"/></body></body>
          <body name="c" pos="1 0 0"><joint name="j3"/><geom size="0.1"/></body>
        </worldbody></mujoco>"#,
    )
    .model;
    let j = |n: &str| &m.joints[m.joint_id(n).unwrap()];
    assert_eq!(j("j1").damping, vec![5.0]);
    assert_eq!(j("j1").armature, vec![0.1]);
    assert_eq!((j("j2").damping[0], j("j2").stiffness[0]), (5.0, 3.0));
    assert_eq!(j("j3").damping, vec![2.0]);
}

#[test]
fn composite_joint_keeps_mujoco_dof_order_ref_and_limits() {
    let m = load(
        r#"<mujoco><compiler angle="radian"/><worldbody><body name="torso" pos="0 0 1.25">
          <joint name="rootx" type="slide" axis="1 0 0" pos="0 0 -1.25"/>
          <joint name="rootz" type="slide" axis="0 0 1" ref="1.25"/>
          <joint name="rooty" type="hinge" axis="0 1 0" range="-1 1"/>
          <geom type="capsule" size="0.05 0.2"/></body></worldbody></mujoco>"#,
    )
    .model;
    assert_eq!(m.joints.len(), 1);
    assert_eq!(m.joints[0].name, "rootx+rootz+rooty");
    assert_eq!(m.qpos0, vec![0.0, 1.25, 0.0]);
    assert_eq!(m.joints[0].limits, vec![(2, -1.0, 1.0)]);
    // qpos = ref puts the body where the XML does; moving rootz by 0.5 lifts it by 0.5
    let mut s = State::reference(&m);
    set_minimal(&m, &mut s, &[0.3, 1.75, 0.4], &[0.1, -0.2, 0.7]).unwrap();
    let p = s.body_pos(&m);
    assert!(
        (p[3] - 0.3).abs() < 1e-12 && (p[5] - 1.75).abs() < 1e-12,
        "{p:?}"
    );
    let (q, v) = (qpos(&m, &s), qvel(&m, &s));
    for (a, b) in q.iter().zip([0.3, 1.75, 0.4]) {
        assert!((a - b).abs() < 1e-12);
    }
    for (a, b) in v.iter().zip([0.1, -0.2, 0.7]) {
        assert!((a - b).abs() < 1e-12);
    }
}

#[test]
fn three_hinges_and_non_orthogonal_pair_round_trip() {
    let m = load(
        r#"<mujoco><worldbody><body name="a" pos="0 0 1">
          <joint name="x" axis="1 0 0"/><joint name="z" axis="0 0 1"/><joint name="y" axis="0 1 0"/>
          <geom size="0.1"/>
          <body name="b" pos="0 0 -0.5"><joint name="s1" axis="2 1 1"/><joint name="s2" axis="0 -1 1"/>
            <geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.04"/></body></body></worldbody></mujoco>"#,
    )
    .model;
    assert_eq!((m.nq, m.nv, m.joints.len()), (5, 5, 2));
    let q = [0.3, -0.5, 1.1, 0.7, -0.9];
    let v = [0.4, 0.2, -0.3, 1.5, 0.6];
    let mut s = State::reference(&m);
    set_minimal(&m, &mut s, &q, &v).unwrap();
    for (a, b) in qpos(&m, &s).iter().zip(q) {
        assert!((a - b).abs() < 1e-10);
    }
    for (a, b) in qvel(&m, &s).iter().zip(v) {
        assert!((a - b).abs() < 1e-10);
    }
    // qvel is the derivative of qpos along the motion (FD of set_minimal)
    let eps = 1e-6;
    let qp: Vec<f64> = q.iter().zip(v).map(|(a, b)| a + eps * b).collect();
    let mut s2 = State::reference(&m);
    set_minimal(&m, &mut s2, &qp, &v).unwrap();
    let (p1, p2) = (s.body_pos(&m), s2.body_pos(&m));
    let lin = s.body_linvel(&m);
    for i in 3..p1.len() {
        let fd = (p2[i] - p1[i]) / eps;
        assert!((fd - lin[i]).abs() < 1e-5, "{i}: {fd} vs {}", lin[i]);
    }
}

#[test]
fn inertia_from_geoms_uses_mujoco_formulas() {
    let m = load(
        r#"<mujoco><worldbody><body name="a"><freejoint/>
          <geom type="box" size="0.1 0.2 0.3" density="500"/>
          <geom type="sphere" size="0.1" pos="1 0 0" mass="2"/></body></worldbody></mujoco>"#,
    )
    .model;
    let b = &m.bodies[1];
    let box_mass = 500.0 * 8.0 * 0.1 * 0.2 * 0.3;
    assert!((b.mass - (box_mass + 2.0)).abs() < 1e-12);
    assert!((b.com[0] - 2.0 / (box_mass + 2.0)).abs() < 1e-12);
}

#[test]
fn errors_name_element_attribute_and_line() {
    let cases = [
        (
            "<mujoco>\n<worldbody>\n<geom size=\"x\"/></worldbody></mujoco>",
            3,
            "size",
        ),
        (
            "<mujoco>\n<worldbody><body>\n<joint type=\"spiral\"/></body></worldbody></mujoco>",
            3,
            "spiral",
        ),
        (
            "<mujoco><worldbody><body><joint/></body></worldbody></mujoco>",
            1,
            "mass",
        ),
        (
            "<mujoco><default><default/></default><worldbody/></mujoco>",
            1,
            "class",
        ),
    ];
    for (xml, line, what) in cases {
        match load_str(xml, "<test>") {
            Err(Error::Mjcf { line: l, msg, .. }) => {
                assert_eq!(l, line, "{msg}");
                assert!(msg.contains(what), "{msg}");
            }
            other => panic!("{xml}: {other:?}"),
        }
    }
    assert!(matches!(
        load_str(
            "<mujoco><worldbody><body><joint type='ball'/><joint/><geom size='.1'/></body></worldbody></mujoco>",
            "<test>"
        ),
        Err(Error::Unsupported(_))
    ));
}

/// Two hinges of one body about different anchors (MuJoCo's humanoid ankle): the body point at
/// each anchor moves as MuJoCo's sequential composition says, `x = A₁ + Q₁(p₂ - p₁) - Q₁Q₂ p₂`.
#[test]
fn hinges_about_different_anchors_compose_in_sequence() {
    let m = load(
        r#"<mujoco><compiler angle="radian"/><worldbody><body name="foot" pos="0 0 1">
          <joint name="ay" axis="0 1 0" pos="0 0 .08"/>
          <joint name="ax" axis="1 0 .5" pos="0 0 .04"/>
          <geom type="sphere" size=".05" pos=".1 0 0"/></body></worldbody></mujoco>"#,
    )
    .model;
    assert_eq!((m.nq, m.nv), (2, 2));
    let (t1, t2) = (0.7, -0.4);
    let mut s = State::reference(&m);
    set_minimal(&m, &mut s, &[t1, t2], &[0.3, -1.1]).unwrap();
    let rot = |axis: nalgebra::Vector3<f64>, t: f64| {
        nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), t)
    };
    let q1 = rot(nalgebra::Vector3::y(), t1);
    let q2 = rot(nalgebra::Vector3::new(1.0, 0.0, 0.5), t2);
    let (p1, p2) = (
        nalgebra::Vector3::new(0.0, 0.0, 0.08),
        nalgebra::Vector3::new(0.0, 0.0, 0.04),
    );
    let a1 = nalgebra::Vector3::new(0.0, 0.0, 1.0) + p1;
    let origin = a1 + q1 * (p2 - p1) - q1 * q2 * p2;
    let (pos, quat) = (s.pose(1).pos, s.pose(1).quat);
    let com = m.bodies[1].com;
    let rot_b = nalgebra::UnitQuaternion::from_quaternion(quat);
    assert!(
        (pos - rot_b * com - origin).norm() < 1e-14,
        "{pos} vs {origin}"
    );
    let back = qvel(&m, &s);
    assert!((qpos(&m, &s)[0] - t1).abs() < 1e-12 && (back[1] + 1.1).abs() < 1e-12);
}

/// `equality/joint` couples two slides by `y = 0.01 + 2 x` and stays satisfied while a force
/// drives one of them; the driven body moves with the analytic acceleration of the coupled pair.
#[test]
fn joint_coupling_holds_and_moves_the_pair_together() {
    let m = load(
        r#"<mujoco><option gravity="0 0 0" timestep="0.001"/><worldbody>
          <body name="a"><joint name="x" type="slide" axis="1 0 0"/>
            <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/></body>
          <body name="b" pos="0 1 0"><joint name="y" type="slide" axis="1 0 0"/>
            <inertial pos="0 0 0" mass="2" diaginertia="1 1 1"/></body></worldbody>
          <equality><joint joint1="y" joint2="x" polycoef="0.01 2"/></equality>
          <actuator><motor joint="x"/></actuator></mujoco>"#,
    )
    .model;
    let mut s = State::reference(&m);
    set_minimal(&m, &mut s, &[0.0, 0.01], &[0.0, 0.0]).unwrap();
    let mut ws = ukemi_engine::Workspace::new(&m);
    let n = 100;
    for _ in 0..n {
        ukemi_engine::step(&m, &mut s, &mut ws, &[3.0]).unwrap();
        let q = qpos(&m, &s);
        assert!((q[1] - 0.01 - 2.0 * q[0]).abs() < 1e-9, "{q:?}");
    }
    // effective inertia m_x + 2² m_y = 9 under force 3: ẍ = 1/3
    let t = n as f64 * 0.001;
    let v = qvel(&m, &s);
    assert!((v[0] - t / 3.0).abs() < 1e-9, "{v:?}");
}

/// A site actuator pushes along the site's z axis, wherever the site sits on the body: four
/// thrusters `gear="0 0 1 0 0 ±c"` with cancelling torques lift the body at `4u/m - g`.
#[test]
fn site_thrust_lifts_at_the_analytic_acceleration() {
    let m = load(
        r#"<mujoco><option timestep="0.01"/><worldbody><body name="x2" pos="0 0 1"><freejoint/>
          <inertial pos="0 0 0" mass="1.5" diaginertia="0.01 0.02 0.03"/>
          <site name="t1" pos="-.14 -.18 .05"/><site name="t2" pos="-.14 .18 .05"/>
          <site name="t3" pos=".14 .18 .05"/><site name="t4" pos=".14 -.18 .05"/></body></worldbody>
          <actuator><motor site="t1" gear="0 0 1 0 0 -.02"/><motor site="t2" gear="0 0 1 0 0 .02"/>
            <motor site="t3" gear="0 0 1 0 0 .02"/><motor site="t4" gear="0 0 1 0 0 -.02"/>
          </actuator></mujoco>"#,
    )
    .model;
    let mut s = State::reference(&m);
    let mut ws = ukemi_engine::Workspace::new(&m);
    let u = 5.0;
    for _ in 0..50 {
        ukemi_engine::step(&m, &mut s, &mut ws, &[u; 4]).unwrap();
    }
    let v = qvel(&m, &s);
    let expected = (4.0 * u / 1.5 - 9.81) * 0.5;
    assert!((v[2] - expected).abs() < 1e-9, "{v:?} vs {expected}");
    assert!(v[3..].iter().all(|w| w.abs() < 1e-9), "{v:?}");
}

/// `<position dampratio>` (MuJoCo's `set0`): `kv = 2 ζ sqrt(kp m)` with `m` the inertia the
/// transmission reflects at qpos0. A point mass 2 kg at 0.5 m on a hinge with armature 0.1,
/// gear 2: `m = (2 · 0.25 + 0.1) / 2²`, so `kv = 2 · 0.7 · sqrt(80 · 0.15)`. A general servo
/// with a positive `biasprm[2]` and `gainprm[0] = -biasprm[1]` is the same damping ratio;
/// with other gains it is kept as written; `kv` and `dampratio` together are an error.
#[test]
fn a_damping_ratio_becomes_the_velocity_gain_of_the_reflected_inertia() {
    let xml = |act: &str| {
        format!(
            r#"<mujoco><worldbody><body name="a"><joint name="j" axis="0 1 0" armature="0.1"/>
            <geom type="sphere" size="0.01" pos="0.5 0 0" mass="2"/>
            <inertial pos="0.5 0 0" mass="2" diaginertia="1e-9 1e-9 1e-9"/></body></worldbody>
            <actuator>{act}</actuator></mujoco>"#
        )
    };
    let kv = |act: &str| load(&xml(act)).model.actuators[0].bias[2];
    let expected = -2.0 * 0.7 * (80.0f64 * (2.0 * 0.25 + 0.1) / 4.0).sqrt();
    let got = kv(r#"<position joint="j" kp="80" gear="2" dampratio="0.7"/>"#);
    assert!(
        (got - expected).abs() < 1e-9 * expected.abs(),
        "{got} vs {expected}"
    );
    let general =
        r#"<general joint="j" gear="2" gainprm="80" biastype="affine" biasprm="0 -80 0.7"/>"#;
    assert!((kv(general) - expected).abs() < 1e-9 * expected.abs());
    let literal = r#"<general joint="j" gainprm="80" biastype="affine" biasprm="0 -40 0.7"/>"#;
    assert_eq!(kv(literal), 0.7);
    let both = load_str(
        &xml(r#"<position joint="j" kp="80" kv="3" dampratio="1"/>"#),
        "<t>",
    );
    let e = both.unwrap_err().to_string();
    assert!(e.contains("kv and dampratio"), "{e}");
}

/// `<position inheritrange>` (MuJoCo): the control range is the joint's (or fixed tendon's)
/// range about its centre, scaled — degrees converted as the joint's range is. MuJoCo 4.0.0
/// compiles these to the ranges asserted here; `ctrlrange` with it is an error, and so is a
/// joint without a range.
#[test]
fn an_inherited_control_range_is_the_scaled_joint_or_tendon_range() {
    let xml = |act: &str| {
        format!(
            r#"<mujoco><worldbody><body name="a"><joint name="j" axis="0 1 0" range="-1 2" limited="true"/>
            <geom size="0.1" mass="1"/><body name="b"><joint name="s" type="slide" range="0 0.04"/>
            <geom size="0.1" mass="1"/></body><body name="c" pos="1 0 0"><joint name="free_hinge"/>
            <geom size="0.1"/></body></body></worldbody>
            <tendon><fixed name="t" range="0 0.3" limited="true"><joint joint="j" coef="0.5"/></fixed></tendon>
            <actuator>{act}</actuator></mujoco>"#
        )
    };
    let range = |act: &str| load(&xml(act)).model.actuators[0].ctrlrange.unwrap();
    let close =
        |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).abs() < 1e-12 && (a.1 - b.1).abs() < 1e-12;
    let deg = std::f64::consts::PI / 180.0;
    assert!(close(
        range(r#"<position joint="j" kp="10" inheritrange="1"/>"#),
        (-deg, 2.0 * deg)
    ));
    let half = range(r#"<position joint="j" kp="10" inheritrange="0.5"/>"#);
    assert!(close(half, (-0.25 * deg, 1.25 * deg)), "{half:?}");
    assert!(close(
        range(r#"<position joint="s" kp="10" inheritrange="2"/>"#),
        (-0.02, 0.06)
    ));
    assert!(close(
        range(r#"<position tendon="t" kp="10" inheritrange="1"/>"#),
        (0.0, 0.3)
    ));
    for (act, what) in [
        (
            r#"<position joint="j" kp="10" inheritrange="1" ctrlrange="0 1"/>"#,
            "ctrlrange and inheritrange",
        ),
        (
            r#"<position joint="free_hinge" kp="10" inheritrange="1"/>"#,
            "needs a limited joint",
        ),
    ] {
        let e = load_str(&xml(act), "<t>").unwrap_err().to_string();
        assert!(e.contains(what), "{e}");
    }
}
