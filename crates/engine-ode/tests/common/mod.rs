//! Shared helpers of the ODE engine's integration tests.
#![allow(dead_code, unused_imports)]

pub use realitygap_core::testing::{
    cube, final_angles_deg, mico2, official_robot, paper_data, scene, with_official_robot,
    workspace, wrist,
};

use realitygap_core::controller::{prepare, simulate, RunError, RunOptions, RunOutcome};
use realitygap_core::engine::{
    EngineError, EngineSettings, ModelVariation, SettingValue, Simulation,
};
use realitygap_core::params::PhysicalParams;
use realitygap_core::robot::{PackageResolver, RobotModel};
use realitygap_core::scene::Scene;
use realitygap_core::Vec3;
use realitygap_engine_ode::{OdeEngine, OdeSimulation};
use std::path::{Path, PathBuf};

/// Settings from `key=value` pairs.
pub fn settings(pairs: &[&str]) -> EngineSettings {
    pairs
        .iter()
        .map(|p| {
            let (k, v) = p.split_once('=').unwrap();
            (k.to_string(), SettingValue::parse(v))
        })
        .collect()
}

/// Runs a scene through ODE with `pairs` as settings.
pub fn run_ode(scene: &Scene, robot: &RobotModel, pairs: &[&str]) -> RunOutcome {
    scene.validate(robot).unwrap();
    simulate(
        &OdeEngine,
        scene,
        robot,
        &settings(pairs),
        &RunOptions::default(),
    )
    .unwrap()
}

/// A scene with one pendulum (its force limit and upper stop given): a 1 kg point-like mass 0.1 m out along x
/// on a hinge about y, at rest horizontal, so gravity pulls it with
/// 0.981 N m about +y.
pub struct Pendulum {
    dir: PathBuf,
    /// Its scene (one actuator, `hinge`, kv 10).
    pub scene: Scene,
    /// Its robot (`stand`, `hinge`, `arm`).
    pub robot: RobotModel,
}

/// Gravity torque on the horizontal pendulum, N m.
pub const PENDULUM_TORQUE_NM: f64 = 0.981;
/// Its inertia about the hinge, kg m^2.
pub const PENDULUM_INERTIA: f64 = 0.01 + 1e-4;

/// Writes the pendulum's URDF and scene into a temporary folder (removed
/// on drop) named after `tag`.
pub fn pendulum(tag: &str, force_limit: f64, upper_limit_rad: f64) -> Pendulum {
    let dir = std::env::temp_dir().join(format!(
        "realitygap-ode-pendulum-{tag}-{}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let urdf = format!(
        r#"<robot name="pendulum">
  <link name="stand">
    <inertial><mass value="1"/><inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial>
  </link>
  <joint name="hinge" type="revolute">
    <parent link="stand"/><child link="arm"/>
    <origin xyz="0 0 1"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="{upper_limit_rad}" effort="100" velocity="10"/>
  </joint>
  <link name="arm">
    <inertial><origin xyz="0.1 0 0"/><mass value="1"/><inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial>
    <collision><origin xyz="0.1 0 0"/><geometry><sphere radius="0.01"/></geometry></collision>
  </link>
</robot>"#
    );
    let urdf_path = dir.join("pendulum.urdf");
    std::fs::write(&urdf_path, urdf).unwrap();
    let toml = format!(
        r#"name = "pendulum"
duration_s = 1.0
[robot]
urdf = {:?}
base_position_m = [0, 0, 0]
[controller]
gain_per_s = 10.0
max_speed_deg_s = 30.0
period_s = 0.05
[[actuator]]
joint = "hinge"
kv = 10.0
force_limit = {force_limit:?}
[[schedule]]
t_s = 0.0
[[track]]
role = "tip"
link = "arm"
"#,
        urdf_path.display().to_string()
    );
    let scene = Scene::from_toml_str(&toml, &dir.join("pendulum.toml")).unwrap();
    let robot = RobotModel::from_urdf_file(&urdf_path, &PackageResolver::new()).unwrap();
    scene.validate(&robot).unwrap();
    Pendulum { dir, scene, robot }
}

impl Drop for Pendulum {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.dir).ok();
    }
}

/// The pendulum's joint angle, rad.
pub fn angle(sim: &OdeSimulation) -> f64 {
    let mut q = [0.0];
    sim.joint_angles_rad(&mut q);
    q[0]
}

/// Mean joint velocity over `n` steps, rad/s.
pub fn velocity_over(sim: &mut OdeSimulation, n: u64) -> f64 {
    let before = angle(sim);
    sim.step_n(n).unwrap();
    (angle(sim) - before) / (n as f64 * sim.timestep_s())
}

/// Parameters from TOML text (named `params.toml` in errors).
pub fn params(text: &str) -> PhysicalParams {
    PhysicalParams::from_toml_str(text, Path::new("params.toml")).unwrap()
}

/// Loads `scene` with `robot` into ODE with `pairs` as settings and the
/// physical parameters `params`, as a run does: core's checks and
/// [`PhysicalParams::apply`] first, then the engine's `load_with`.
pub fn load_with_params(
    scene: &Scene,
    robot: &RobotModel,
    pairs: &[&str],
    params: &PhysicalParams,
) -> Result<OdeSimulation, EngineError> {
    let (scene, robot) = match prepare(&OdeEngine, scene, robot, params) {
        Ok(prepared) => prepared,
        Err(RunError::Engine(e)) => return Err(e),
        Err(e) => panic!("{e}"),
    };
    OdeSimulation::load_with(
        &scene,
        &robot,
        &settings(pairs),
        &ModelVariation::default(),
        params,
    )
}
