//! State-dependent actuator bias (position and velocity servos, MuJoCo's affine `general`
//! actuator): `τ_dof += gear (bias₀ + bias₁ gear q + bias₂ gear q̇)`, evaluated at the current
//! configuration and the previous midpoint velocity, like springs and motor inputs (explicit).
use crate::joints::geometry::JointFrame;
use crate::model::Model;
use crate::state::State;

/// Add the bias forces of the actuators on joint `ji` to `tau` (its free dofs). `jf` is the
/// joint's free Jacobian at the current configuration.
pub(crate) fn add_servo_bias(
    model: &Model,
    state: &State,
    ji: usize,
    frame: &JointFrame,
    jf: &[f64],
    tau: &mut [f64],
) {
    let joint = &model.joints[ji];
    let mut coords = [0.0; 7];
    let mut have_coords = false;
    for act in model.actuators.iter().filter(|a| a.joint == ji) {
        if act.bias == [0.0; 3] {
            continue;
        }
        if !have_coords {
            frame.coordinates(joint, &mut coords[..joint.nq()]);
            have_coords = true;
        }
        let row = &jf[12 * act.dof..12 * act.dof + 12];
        let mut rate = 0.0;
        for (side, b) in [(0, joint.parent), (1, joint.child)] {
            if b > 0 {
                let (v, w) = state.velocity(b);
                for i in 0..3 {
                    rate += row[6 * side + i] * v[i] + row[6 * side + 3 + i] * w[i];
                }
            }
        }
        let length = act.gear * coords[act.dof];
        tau[act.dof] +=
            act.gear * (act.bias[0] + act.bias[1] * length + act.bias[2] * act.gear * rate);
    }
}
