//! The pre-run stability check of MuJoCo's explicit integrators.
//!
//! MuJoCo's `Euler` integrator treats joint damping (`dof_damping`)
//! implicitly but a velocity actuator's damping explicitly: a servo with
//! gain `kv` on a joint whose effective inertia is `I` (kg m^2) updates the
//! joint's velocity error `e` once per step as `e' = (1 - kv dt / I) e`.
//! That recurrence is stable only while `|1 - kv dt / I| < 1`, that is
//! `kv dt / I < 2`; beyond it the error grows by the factor
//! `kv dt / I - 1` each step, flipping sign at every step, until the force
//! limit clips the servo and the joint moves in a bounded, chaotic way that
//! no NaN check sees. `RK4` integrates the same decay `de/dt = -(kv/I) e`
//! with a stability interval of `kv dt / I < 2.785` on the negative real
//! axis. `implicit` and `implicitfast` include the actuator's velocity
//! derivative in the step and are stable at any `kv dt / I`.
//!
//! The effective inertia of a controlled joint is the inertia it moves
//! when the other joints are free: `I_eff = 1 / (M^-1)_jj`, from the
//! compiled model's joint-space inertia matrix `M` (armature included) at
//! the initial pose. It is never above the diagonal entry `M_jj`, and
//! `kv_j dt (M^-1)_jj` is a lower bound of the largest eigenvalue of
//! `dt M^-1 K` (`K` the diagonal of servo gains), whose value above 2 is
//! the exact instability condition of the coupled arm. So a joint found
//! past the bound here makes the whole step unstable: the check refuses
//! nothing that is stable at the initial pose. Other poses have other
//! inertias; the runtime check of the run health catches what the pose
//! changes.

use crate::ENGINE_NAME;
use mujoco_rs::mujoco_c;
use mujoco_rs::prelude::*;
use realitygap_core::engine::StabilityIssue;

/// The quantity the check bounds.
pub const QUANTITY: &str = "kv*dt/I_eff";

/// The bound of `kv dt / I` for MuJoCo's Euler integrator (explicit in the
/// actuators' damping).
pub const EULER_BOUND: f64 = 2.0;

/// The bound of `kv dt / I` for classical RK4 on a pure decay: the
/// stability interval of its polynomial `1 + z + z^2/2 + z^3/6 + z^4/24`
/// on the negative real axis, |z| < 2.785.
pub const RK4_BOUND: f64 = 2.785;

/// The explicit-integration bound of the model's integrator; `None` for
/// the implicit ones.
pub fn bound_of(integrator: i32) -> Option<(f64, &'static str)> {
    if integrator == mujoco_c::mjtIntegrator::mjINT_EULER as i32 {
        Some((EULER_BOUND, "Euler"))
    } else if integrator == mujoco_c::mjtIntegrator::mjINT_RK4 as i32 {
        Some((RK4_BOUND, "RK4"))
    } else {
        None
    }
}

/// One controlled joint's servo on the model: name, DOF and actuator.
#[derive(Debug, Clone)]
pub struct ServoJoint<'a> {
    /// The joint's name.
    pub name: &'a str,
    /// Its DOF address (`qvel` index).
    pub dof: usize,
    /// The actuator driving it.
    pub actuator: usize,
}

/// The damping a joint-transmission actuator puts on its DOF, N m s/rad:
/// `-biasprm[2] * gear^2` (the force is `gain * ctrl + bias0 + bias1 * length
/// + bias2 * velocity`, the actuator velocity is `gear * qvel`, and the
/// force reaches the DOF multiplied by `gear`).
pub fn servo_damping(model: &MjModel, actuator: usize) -> f64 {
    let gear = model.actuator_gear()[actuator][0];
    let affine = model.actuator_biastype()[actuator] == mujoco_c::mjtBias::mjBIAS_AFFINE;
    if affine {
        -model.actuator_biasprm()[actuator][2] * gear * gear
    } else {
        0.0
    }
}

/// The dense joint-space inertia matrix `M` (row-major, `nv x nv`, kg m^2
/// on hinge DOFs) of `data`'s current pose; `mj_forward` must have run.
fn full_inertia(data: &mut MjData<Box<MjModel>>) -> Vec<f64> {
    let nv = data.model().ffi().nv as usize;
    let mut dense = vec![0.0; nv * nv];
    // SAFETY: model and data belong together; `qM` was computed by the
    // caller's forward pass; `dense` holds nv*nv numbers as mj_fullM
    // writes.
    unsafe {
        let d = data.ffi_mut() as *mut mujoco_c::mjData;
        let m = data.model().ffi() as *const mujoco_c::mjModel;
        mujoco_c::mj_fullM(m, d, dense.as_mut_ptr());
    }
    dense
}

/// The lower Cholesky factor of the symmetric positive definite `a`
/// (`n x n`, row-major); `None` when it is not positive definite.
fn cholesky(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let s = a[i * n + j] - (0..j).map(|k| l[i * n + k] * l[j * n + k]).sum::<f64>();
            if i == j {
                if s <= 0.0 || !s.is_finite() {
                    return None;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    Some(l)
}

/// `(M^-1)_jj` from the Cholesky factor `l` of `M`: the squared norm of
/// `L^-1 e_j`.
fn inverse_diagonal(l: &[f64], n: usize, j: usize) -> f64 {
    let mut y = vec![0.0; n];
    for i in j..n {
        let rhs = if i == j { 1.0 } else { 0.0 };
        let s = rhs - (j..i).map(|k| l[i * n + k] * y[k]).sum::<f64>();
        y[i] = s / l[i * n + i];
    }
    y.iter().map(|v| v * v).sum()
}

/// The effective inertia of each DOF in `dofs`, kg m^2: `1 / (M^-1)_jj` at
/// the current pose (see the module documentation).
pub fn effective_inertias(data: &mut MjData<Box<MjModel>>, dofs: &[usize]) -> Option<Vec<f64>> {
    let nv = data.model().ffi().nv as usize;
    let l = cholesky(&full_inertia(data), nv)?;
    Some(
        dofs.iter()
            .map(|&j| 1.0 / inverse_diagonal(&l, nv, j))
            .collect(),
    )
}

/// The servos of `joints` past the bound of the model's explicit
/// integrator, worst first (see the module documentation); empty under
/// an implicit integrator. `data` is at its initial pose, after
/// `mj_forward`.
pub fn check(data: &mut MjData<Box<MjModel>>, joints: &[ServoJoint<'_>]) -> Vec<StabilityIssue> {
    let (integrator, dt) = {
        let opt = data.model().opt();
        (opt.integrator, opt.timestep)
    };
    let Some((bound, name)) = bound_of(integrator) else {
        return Vec::new();
    };
    let dofs: Vec<usize> = joints.iter().map(|j| j.dof).collect();
    let Some(inertias) = effective_inertias(data, &dofs) else {
        return Vec::new();
    };
    let mut issues: Vec<StabilityIssue> = joints
        .iter()
        .zip(inertias)
        .filter_map(|(j, i_eff)| {
            let kv = servo_damping(data.model(), j.actuator);
            let ratio = kv * dt / i_eff;
            (ratio >= bound).then(|| issue(j.name, kv, dt, i_eff, ratio, bound, name))
        })
        .collect();
    issues.sort_by(|a, b| b.value.total_cmp(&a.value));
    issues
}

/// The issue of one joint, with its numbers and the fixes.
fn issue(
    joint: &str,
    kv: f64,
    dt: f64,
    i_eff: f64,
    ratio: f64,
    bound: f64,
    integrator: &str,
) -> StabilityIssue {
    // Half the stable timestep: the error then decays without flipping
    // sign (kv dt / I <= 1), as a damper should.
    let safe_dt = i_eff / kv;
    StabilityIssue {
        joint: Some(joint.to_string()),
        quantity: QUANTITY.to_string(),
        value: ratio,
        bound,
        message: format!(
            "joint \"{joint}\": {QUANTITY} = {kv} N m s/rad * {dt} s / {i_eff:.4e} kg m^2 = {ratio:.3}, \
             past the bound {bound} of {ENGINE_NAME}'s {integrator} integrator, which integrates the \
             velocity servo's damping explicitly (I_eff = 1/(M^-1)_jj at the initial pose, armature \
             included); fix: set integrator = \"implicitfast\", or timestep_s below {safe_dt:.3e} s \
             (kv*dt/I_eff <= 1)"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::MujocoEngine;
    use realitygap_core::controller::{load_prepared, refuse_unstable, RunError, RunOptions};
    use realitygap_core::engine::{EngineError, EngineSettings, SettingValue};
    use realitygap_core::params::PhysicalParams;
    use realitygap_core::robot::{PackageResolver, RobotModel};
    use realitygap_core::scene::Scene;
    use std::path::Path;

    /// A heavy upper link on j1 and a light lower link on j2, both hinges
    /// about y with the centres of mass on their axes: j2's inertia about
    /// its axis is 1e-4 kg m^2 (plus nothing: no armature).
    const ARM: &str = r#"<robot name="light">
  <link name="world"/>
  <link name="base"><inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <link name="upper"><inertial><mass value="5"/><inertia ixx="0.05" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.05"/></inertial></link>
  <link name="lower"><inertial><mass value="0.1"/><inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial></link>
  <joint name="fix" type="fixed"><parent link="world"/><child link="base"/></joint>
  <joint name="j1" type="revolute"><parent link="base"/><child link="upper"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="100" velocity="5"/></joint>
  <joint name="j2" type="revolute"><parent link="upper"/><child link="lower"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="100" velocity="5"/></joint>
</robot>"#;

    const SCENE: &str = r#"
name = "light"
duration_s = 1.0
[robot]
urdf = "light.urdf"
base_position_m = [0, 0, 0]
[controller]
gain_per_s = 10.0
max_speed_deg_s = 30.0
period_s = 0.05
[[actuator]]
joint = "j1"
kv = 10.0
force_limit = 100.0
[[actuator]]
joint = "j2"
kv = 1.0
force_limit = 100.0
[[schedule]]
t_s = 0.0
targets_deg = { j1 = 10.0 }
"#;

    fn load(pairs: &[(&str, SettingValue)], allow: bool) -> Result<Vec<StabilityIssue>, RunError> {
        let robot =
            RobotModel::from_urdf_str(ARM, Path::new("/tmp"), &PackageResolver::new()).unwrap();
        let scene = Scene::from_toml_str(SCENE, Path::new("/tmp/light.toml")).unwrap();
        scene.validate(&robot).unwrap();
        let settings: EngineSettings = pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.clone()))
            .collect();
        let options = RunOptions {
            allow_unstable: allow,
            ..RunOptions::default()
        };
        let sim = load_prepared(
            &MujocoEngine,
            &scene,
            &robot,
            &settings,
            &PhysicalParams::none(),
            &options,
        )?;
        refuse_unstable(&MujocoEngine, sim.as_ref(), &options)?;
        Ok(sim.stability_issues())
    }

    #[test]
    fn a_light_link_is_refused_at_a_coarse_euler_step_and_accepted_when_safe() {
        // j2: kv*dt/I = 1 * 1e-3 / 1e-4 = 10 under Euler.
        let coarse = [
            ("timestep_s", SettingValue::Float(1e-3)),
            ("integrator", SettingValue::Text("euler".into())),
        ];
        let e = load(&coarse, false).unwrap_err().to_string();
        assert!(e.contains("joint \"j2\""), "{e}");
        assert!(e.contains("= 10.0"), "{e}");
        assert!(e.contains("implicitfast"), "{e}");
        assert!(e.contains("timestep_s below 9.98"), "{e}");
        assert!(!e.contains("\"j1\""), "{e}");
        assert!(matches!(
            load(&coarse, false),
            Err(RunError::Engine(EngineError::UnstableSettings { .. }))
        ));
        // Allowed: the issue is still reported, with the effective inertia
        // of j2 (the heavy j1 moves little: I_eff is about 1e-4).
        let issues = load(&coarse, true).unwrap();
        assert_eq!(issues.len(), 1);
        assert_eq!(issues[0].joint.as_deref(), Some("j2"));
        assert!((issues[0].value - 10.0).abs() < 0.05, "{}", issues[0].value);
        assert_eq!(issues[0].bound, EULER_BOUND);
        // RK4 has a wider bound, still far exceeded.
        let rk4 = [
            ("timestep_s", SettingValue::Float(1e-3)),
            ("integrator", SettingValue::Text("rk4".into())),
        ];
        assert_eq!(load(&rk4, true).unwrap()[0].bound, RK4_BOUND);
        // Safe: a timestep with kv*dt/I = 1, or an implicit integrator.
        let fine = [
            ("timestep_s", SettingValue::Float(1e-4)),
            ("integrator", SettingValue::Text("euler".into())),
        ];
        assert_eq!(load(&fine, false).unwrap(), vec![]);
        let implicit = [
            ("timestep_s", SettingValue::Float(1e-3)),
            ("integrator", SettingValue::Text("implicitfast".into())),
        ];
        assert_eq!(load(&implicit, false).unwrap(), vec![]);
    }

    #[test]
    fn cholesky_inverse_diagonal_matches_a_hand_inverse() {
        // [[4, 2], [2, 3]]^-1 = [[3, -2], [-2, 4]] / 8.
        let a = [4.0, 2.0, 2.0, 3.0];
        let l = cholesky(&a, 2).unwrap();
        assert!((inverse_diagonal(&l, 2, 0) - 3.0 / 8.0).abs() < 1e-12);
        assert!((inverse_diagonal(&l, 2, 1) - 4.0 / 8.0).abs() < 1e-12);
        assert!(cholesky(&[1.0, 2.0, 2.0, 1.0], 2).is_none());
    }
}
