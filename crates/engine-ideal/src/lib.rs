//! The physics-free model as an engine: `ideal`, a servo that tracks its
//! target perfectly. Every controlled joint moves at exactly its velocity
//! target (or sits at its position target), the tracked links follow by
//! forward kinematics of the robot model, the scene's objects stay where
//! they are. No mass, no gravity, no contact.
//!
//! It is the baseline every engine must beat (METHOD.md: the commanded
//! joint trajectory with perfect tracking scores about as well as the best
//! engines at their defaults), and as an engine it is a source like any
//! other: `run`, `reproduce` and `compare` show its row, and `tune --engine
//! ideal` fits what has no physics to fit — the controller's delay, the
//! encoder offsets and the actuator stage (`[actuator]`, the same stage in
//! front of every engine's servo) — which is the physics-free model behind
//! the fitted actuator stage.
//!
//! Effort commands have no meaning without dynamics: they are an error.

#![forbid(unsafe_code)]

use realitygap_core::engine::{
    check_servo_commands, CommandKind, CommandSupport, Engine, EngineError, EngineSettings,
    ModelVariation, ObjectState, ServoCommand, SettingInfo, SettingsReader, SimState, Simulation,
};
use realitygap_core::params::{ParamSupport, PhysicalParams};
use realitygap_core::pose::{Pose, Vec3};
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::{Scene, TrackTarget};

/// The engine's name on the command line and in result directories.
pub const ENGINE_NAME: &str = realitygap_core::engine::PHYSICS_FREE_ENGINE;

/// The timestep used when the settings give none, s.
pub const DEFAULT_TIMESTEP_S: f64 = 1e-3;

/// The settings accepted in `[engine.ideal]` and by `--set`.
pub const SETTINGS: &[SettingInfo] = &[SettingInfo {
    key: "timestep_s",
    help: "integration timestep, s (> 0, at most 1); default 0.001 (a velocity target is integrated exactly over each step)",
}];

/// How the ideal servo takes each kind of command.
pub const COMMAND_SUPPORT: [CommandSupport; 3] = [
    CommandSupport {
        kind: CommandKind::Velocity,
        mechanism: "the joint moves at exactly the target velocity",
    },
    CommandSupport {
        kind: CommandKind::Position,
        mechanism: "the joint is at the target position at once",
    },
    CommandSupport {
        kind: CommandKind::Effort,
        mechanism: "refused: without dynamics an effort moves nothing",
    },
];

/// The physics-free engine.
#[derive(Debug, Default, Clone, Copy)]
pub struct IdealEngine;

fn timestep(settings: &EngineSettings) -> Result<f64, EngineError> {
    let r = SettingsReader::new(ENGINE_NAME, settings, SETTINGS)?;
    Ok(r.number(
        "timestep_s",
        |v| v > 0.0 && v <= 1.0,
        "greater than 0 s and at most 1 s",
    )?
    .unwrap_or(DEFAULT_TIMESTEP_S))
}

impl Engine for IdealEngine {
    fn name(&self) -> &'static str {
        ENGINE_NAME
    }

    fn version(&self) -> String {
        "physics-free (perfect tracking)".to_string()
    }

    fn default_timestep_s(&self) -> f64 {
        DEFAULT_TIMESTEP_S
    }

    fn settings_help(&self) -> Vec<SettingInfo> {
        SETTINGS.to_vec()
    }

    fn check_settings(&self, settings: &EngineSettings) -> Result<f64, EngineError> {
        timestep(settings)
    }

    fn param_support(&self) -> Vec<ParamSupport> {
        // Only the controller's keys (core applies them): nothing physical.
        Vec::new()
    }

    fn command_support(&self) -> Vec<CommandSupport> {
        COMMAND_SUPPORT.to_vec()
    }

    fn load_with(
        &self,
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
        _params: &PhysicalParams,
    ) -> Result<Box<dyn Simulation>, EngineError> {
        // The model has no masses or friction to vary, but a bad factor is
        // the same error as in every engine.
        variation.check().map_err(load_error)?;
        Ok(Box::new(IdealSimulation::load(scene, robot, settings)?))
    }
}

/// One tracked body: a link (its index) or an object (its index).
#[derive(Debug, Clone, Copy)]
enum Tracked {
    Link(usize),
    Object(usize),
}

/// A physics-free simulation of a scene.
#[derive(Debug, Clone)]
pub struct IdealSimulation {
    robot: RobotModel,
    base: Pose,
    dt: f64,
    time_s: f64,
    /// Robot joint index of each controlled joint.
    joints: Vec<usize>,
    /// Positions of every robot joint (held joints at their scene angles).
    positions: Vec<f64>,
    /// Each controlled joint's command.
    commands: Vec<ServoCommand>,
    tracked: Vec<Tracked>,
    objects: Vec<(String, Pose)>,
    link_poses: Vec<Pose>,
    scene: Scene,
}

fn load_error(message: impl Into<String>) -> EngineError {
    EngineError::Load {
        engine: ENGINE_NAME.to_string(),
        message: message.into(),
    }
}

impl IdealSimulation {
    /// The simulation of `scene` with `robot`, at rest with every
    /// controlled joint at 0.
    pub fn load(
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
    ) -> Result<IdealSimulation, EngineError> {
        let dt = timestep(settings)?;
        scene
            .validate(robot)
            .map_err(|e| load_error(e.to_string()))?;
        let mut positions = vec![0.0; robot.joints.len()];
        for (name, &a) in &scene.robot.held_joints_rad {
            let j = robot
                .joint_by_name(name)
                .ok_or_else(|| load_error(format!("the robot has no held joint \"{name}\"")))?;
            positions[j] = a;
        }
        let joints = scene
            .actuators
            .iter()
            .map(|a| {
                robot
                    .joint_by_name(&a.joint)
                    .ok_or_else(|| load_error(format!("the robot has no joint \"{}\"", a.joint)))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let tracked = scene
            .tracked
            .iter()
            .map(|t| match &t.target {
                TrackTarget::Link(l) => robot
                    .link_by_name(l)
                    .map(Tracked::Link)
                    .ok_or_else(|| load_error(format!("the robot has no link \"{l}\""))),
                TrackTarget::Object(o) => scene
                    .objects
                    .iter()
                    .position(|x| &x.name == o)
                    .map(Tracked::Object)
                    .ok_or_else(|| load_error(format!("the scene has no object \"{o}\""))),
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut sim = IdealSimulation {
            base: scene.robot.base,
            dt,
            time_s: 0.0,
            commands: vec![ServoCommand::velocity(0.0); joints.len()],
            joints,
            positions,
            tracked,
            objects: scene
                .objects
                .iter()
                .map(|o| (o.name.clone(), o.pose))
                .collect(),
            link_poses: Vec::new(),
            robot: robot.clone(),
            scene: scene.clone(),
        };
        sim.update_links();
        Ok(sim)
    }

    fn update_links(&mut self) {
        self.link_poses = self.robot.forward_kinematics(&self.base, &self.positions);
    }

    fn velocity(&self, i: usize) -> f64 {
        match self.commands[i].kind {
            CommandKind::Velocity => self.commands[i].value,
            _ => 0.0,
        }
    }
}

impl Simulation for IdealSimulation {
    fn timestep_s(&self) -> f64 {
        self.dt
    }

    fn time_s(&self) -> f64 {
        self.time_s
    }

    fn joint_count(&self) -> usize {
        self.joints.len()
    }

    fn tracked_count(&self) -> usize {
        self.tracked.len()
    }

    fn set_joint_angles_rad(&mut self, rad: &[f64]) -> Result<(), EngineError> {
        if rad.len() != self.joints.len() {
            return Err(EngineError::Usage {
                engine: ENGINE_NAME.into(),
                message: format!("{} finite joint angles are needed", self.joints.len()),
            });
        }
        if let Some(i) = rad.iter().position(|a| !a.is_finite()) {
            return Err(EngineError::Usage {
                engine: ENGINE_NAME.into(),
                message: format!(
                    "joint \"{}\": angle {} is not finite",
                    self.scene.actuators[i].joint, rad[i]
                ),
            });
        }
        for (&j, &a) in self.joints.iter().zip(rad) {
            self.positions[j] = a;
        }
        self.update_links();
        Ok(())
    }

    fn set_joint_velocity_targets(&mut self, rad_s: &[f64]) {
        for (c, &v) in self.commands.iter_mut().zip(rad_s) {
            *c = ServoCommand::velocity(v);
        }
    }

    fn set_joint_commands(&mut self, commands: &[ServoCommand]) -> Result<(), EngineError> {
        check_servo_commands(ENGINE_NAME, &self.scene, commands)?;
        if let Some(i) = commands.iter().position(|c| c.kind == CommandKind::Effort) {
            return Err(EngineError::Usage {
                engine: ENGINE_NAME.into(),
                message: format!(
                    "joint \"{}\" takes an effort command: the physics-free model has no dynamics, so no effort moves it",
                    self.scene.actuators[i].joint
                ),
            });
        }
        self.commands = commands.to_vec();
        for (&j, c) in self.joints.iter().zip(commands) {
            if c.kind == CommandKind::Position {
                self.positions[j] = c.value;
            }
        }
        self.update_links();
        Ok(())
    }

    fn step(&mut self) -> Result<(), EngineError> {
        self.step_n(1)
    }

    fn step_n(&mut self, n: u64) -> Result<(), EngineError> {
        let h = n as f64 * self.dt;
        for i in 0..self.joints.len() {
            let v = self.velocity(i);
            self.positions[self.joints[i]] += v * h;
        }
        self.time_s += h;
        self.update_links();
        Ok(())
    }

    fn joint_angles_rad(&self, out: &mut [f64]) {
        for (o, &j) in out.iter_mut().zip(&self.joints) {
            *o = self.positions[j];
        }
    }

    fn joint_velocities_rad_s(&self, out: &mut [f64]) -> Result<(), EngineError> {
        for (i, o) in out.iter_mut().enumerate() {
            *o = self.velocity(i);
        }
        Ok(())
    }

    fn tracked_poses(&self, out: &mut [Pose]) {
        for (o, t) in out.iter_mut().zip(&self.tracked) {
            *o = match *t {
                Tracked::Link(l) => self.link_poses[l],
                Tracked::Object(k) => self.objects[k].1,
            };
        }
    }

    fn state(&self) -> Result<SimState, EngineError> {
        let n = self.joints.len();
        let mut angles = vec![0.0; n];
        self.joint_angles_rad(&mut angles);
        let velocities: Vec<f64> = (0..n).map(|i| self.velocity(i)).collect();
        let all_velocity = self
            .commands
            .iter()
            .all(|c| c.kind == CommandKind::Velocity);
        Ok(SimState {
            time_s: self.time_s,
            joint_angles_rad: angles,
            joint_velocities_rad_s: velocities.clone(),
            joint_velocity_targets_rad_s: velocities,
            servo_commands: if all_velocity {
                Vec::new()
            } else {
                self.commands.clone()
            },
            objects: self
                .objects
                .iter()
                .map(|(name, pose)| ObjectState {
                    name: name.clone(),
                    pose: *pose,
                    linear_velocity_m_s: Vec3::ZERO,
                    angular_velocity_rad_s: Vec3::ZERO,
                })
                .collect(),
            native: None,
        })
    }

    fn set_state(&mut self, state: &SimState) -> Result<(), EngineError> {
        let names: Vec<&str> = self.objects.iter().map(|(n, _)| n.as_str()).collect();
        state
            .check(self.joints.len(), &names)
            .map_err(|message| EngineError::State {
                engine: ENGINE_NAME.into(),
                message,
            })?;
        for (&j, &a) in self.joints.iter().zip(&state.joint_angles_rad) {
            self.positions[j] = a;
        }
        // Objects do not move here: they keep the pose handed over.
        for ((_, pose), o) in self.objects.iter_mut().zip(&state.objects) {
            *pose = o.pose;
        }
        self.time_s = state.time_s;
        if state.servo_commands.is_empty() {
            self.set_joint_velocity_targets(&state.joint_velocity_targets_rad_s);
        } else {
            let angles = state.joint_angles_rad.clone();
            self.set_joint_commands(&state.servo_commands)?;
            // A position command set with a state keeps the state's angles.
            for (&j, &a) in self.joints.iter().zip(&angles) {
                self.positions[j] = a;
            }
        }
        self.update_links();
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use realitygap_core::testing::{mico2, scene};

    #[test]
    fn the_joint_moves_at_exactly_its_target_and_the_wrist_follows_by_kinematics() {
        let s = scene("scene1_single_joint");
        let robot = mico2();
        let mut sim = IdealSimulation::load(&s, &robot, &EngineSettings::new()).unwrap();
        let mut v = vec![0.0; 6];
        v[1] = -0.5;
        sim.set_joint_velocity_targets(&v);
        sim.step_n(1000).unwrap();
        let mut q = vec![0.0; 6];
        sim.joint_angles_rad(&mut q);
        assert!((q[1] + 0.5).abs() < 1e-12, "{q:?}");
        let mut p = vec![Pose::IDENTITY; s.tracked.len()];
        sim.tracked_poses(&mut p);
        let mut full = vec![0.0; robot.joints.len()];
        full[robot.joint_by_name("m1n6s300_joint_2").unwrap()] = -0.5;
        let want = robot
            .link_pose(
                &s.robot.base,
                &full,
                robot.link_by_name("m1n6s300_link_6").unwrap(),
            )
            .unwrap();
        assert!(p[0].position_m.distance(want.position_m) < 1e-12);
        assert!(sim
            .set_joint_commands(&[ServoCommand::effort(1.0); 6])
            .unwrap_err()
            .to_string()
            .contains("no dynamics"));
    }
}
