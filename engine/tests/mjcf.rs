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
