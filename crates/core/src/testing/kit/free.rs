//! Free bodies: scenes of objects alone (no robot), as the tossed cubes'
//! study runs them. A box thrown in free flight against the analytic
//! parabola; a box spinning without gravity or torque, whose angular
//! momentum and kinetic energy must hold; a cube dropped flat onto the
//! ground, which must come to rest on its face where it fell, neither
//! sinking nor sliding nor tipping. Every check runs at
//! [`FreeBody::settings`] (the toss study's, a 1 ms timestep) over the
//! spec's [`KitSpec::settings`].
//!
//! An engine without dynamics ([`KitSpec::dynamics`] false) must leave
//! every object where the scene puts it.

use super::{load, report, settings, KitSpec};
use crate::controller::{ControlParams, ControllerLoop, RunOptions};
use crate::engine::{Engine, EngineSettings, ObjectState, Simulation};
use crate::params::PhysicalParams;
use crate::pose::Vec3;
use crate::robot::RobotModel;
use crate::scene::Scene;
use std::path::Path;

/// What the free-body checks allow an engine.
#[derive(Debug, Clone, Copy)]
pub struct FreeBody {
    /// Settings of the free-body checks (`key=value`), over
    /// [`KitSpec::settings`].
    pub settings: &'static [&'static str],
    /// Free flight: the largest gap from the parabola at time `t`, as a
    /// multiple of `g t h` (`h` the timestep: a first-order integrator of
    /// constant gravity is off by `g t h / 2`), plus
    /// [`FreeBody::flight_floor_m`].
    pub flight_gth: f64,
    /// Free flight: the gap allowed at any time whatever the timestep
    /// (rounding), m.
    pub flight_floor_m: f64,
    /// Torque-free rotation over 2 s: the largest relative change of the
    /// angular momentum (world frame, as a vector) and of the kinetic
    /// energy.
    pub rotation: [f64; 2],
    /// The cube dropped flat, after 1.5 s: how far below its rest height
    /// it may be (sinking), m.
    pub rest_sink_m: f64,
    /// The same: how far it may have moved sideways, m.
    pub rest_drift_m: f64,
    /// The same: how far it may have tilted, rad.
    pub rest_tilt_rad: f64,
    /// A cube given friction 0.2 sliding on the engine's own ground: the
    /// coefficient its slide shows, as a multiple of 0.2 (1: the object's
    /// friction is the contact's; Bullet multiplies it by the ground's).
    pub slide_friction_factor: f64,
}

impl FreeBody {
    /// What the contract asks of a double-precision engine at a 1 ms step:
    /// flight within the first-order bound `g t h / 2` (semi-implicit
    /// Euler is off by exactly that: 2 % of room for rounding, and 1e-9 m);
    /// the angular momentum and energy of a torque-free body held to 1 %
    /// over 2 s (a first-order step of the gyroscopic term drifts by a few
    /// 1e-4 to 1e-3 at 6 rad/s and 1 ms; an engine that leaves the term out
    /// turns the momentum by tens of percent); a cube
    /// dropped flat from 5 cm at rest on its face within 1 mm of its rest
    /// height, 1 mm of where it fell and 0.01 rad of flat.
    pub const CONTRACT: FreeBody = FreeBody {
        settings: &["timestep_s=0.001"],
        flight_gth: 0.51,
        flight_floor_m: 1e-9,
        rotation: [1e-2, 1e-2],
        rest_sink_m: 1e-3,
        rest_drift_m: 1e-3,
        rest_tilt_rad: 0.01,
        slide_friction_factor: 1.0,
    };
}

/// A scene of free objects alone from TOML text (named `/kit/free.toml`).
pub fn free_scene(text: &str) -> Scene {
    Scene::from_toml_str(text, Path::new("/kit/free.toml")).unwrap_or_else(|e| panic!("{e}"))
}

/// The settings of a free-body check on `scene`.
fn free_settings(engine: &dyn Engine, spec: &KitSpec, scene: &Scene) -> EngineSettings {
    let mut s = scene.settings_for(engine.name());
    s.extend(settings(spec.settings));
    s.extend(settings(spec.free.settings));
    s
}

/// Loads `scene` (objects alone) and gives its objects their initial
/// velocities the way a run does ([`ControllerLoop::start`]).
fn started(engine: &dyn Engine, spec: &KitSpec, scene: &Scene) -> Box<dyn Simulation> {
    let robot = RobotModel::world();
    scene.validate(&robot).unwrap();
    let settings = free_settings(engine, spec, scene);
    let mut sim = load(engine, scene, &robot, &settings, &PhysicalParams::none())
        .unwrap_or_else(|e| panic!("{}: {e}", engine.name()));
    let mut run = ControllerLoop::new(scene, &RunOptions::default(), &ControlParams::default());
    run.start(sim.as_mut())
        .unwrap_or_else(|e| panic!("{}: {e}", engine.name()));
    sim
}

fn object(sim: &dyn Simulation) -> ObjectState {
    sim.state().unwrap().objects.remove(0)
}

const THROWN: &str = r#"
name = "thrown"
duration_s = 1.0
[[object]]
name = "box"
shape = "box"
size_m = [0.1, 0.2, 0.3]
mass_kg = 0.37
position_m = [0.0, 0.0, 1.0]
linear_velocity_m_s = [1.5, -0.5, 3.0]
[[track]]
role = "box"
object = "box"
"#;

/// A box thrown upward with no ground, no spin: its centre on the
/// parabola `p0 + v0 t + g t^2 / 2` at every step for 1 s, within
/// [`FreeBody::flight_gth`] `g t h` + [`FreeBody::flight_floor_m`].
pub fn free_flight(engine: &dyn Engine, spec: &KitSpec) {
    let scene = free_scene(THROWN);
    let mut sim = started(engine, spec, &scene);
    let h = sim.timestep_s();
    let steps = (1.0 / h).round() as u64;
    let (p0, v0, g) = (
        scene.objects[0].pose.position_m,
        scene.objects[0].linear_velocity_m_s,
        scene.gravity_m_s2,
    );
    let mut worst = 0.0_f64;
    let mut worst_ratio = 0.0_f64;
    for n in 1..=steps {
        sim.step().unwrap();
        let t = n as f64 * h;
        let p = object(sim.as_ref()).pose.position_m;
        let want = if spec.dynamics {
            p0 + v0.scale(t) + g.scale(0.5 * t * t)
        } else {
            p0
        };
        let gap = p.distance(want);
        let tolerance = spec.free.flight_gth * g.norm() * t * h + spec.free.flight_floor_m;
        assert!(
            gap <= tolerance,
            "{}: at t = {t:.3} s the thrown box is {gap:e} m from the parabola (tolerance {tolerance:e})",
            engine.name()
        );
        worst = worst.max(gap);
        worst_ratio = worst_ratio.max(gap / tolerance);
    }
    report(engine, "free_flight_gap_m", worst, worst_ratio);
}

const SPUN: &str = r#"
name = "spun"
duration_s = 2.0
gravity_m_s2 = [0.0, 0.0, 0.0]
[[object]]
name = "box"
shape = "box"
size_m = [0.1, 0.2, 0.3]
mass_kg = 1.0
position_m = [0.0, 0.0, 1.0]
angular_velocity_rad_s = [0.5, 0.3, 6.0]
[[track]]
role = "box"
object = "box"
"#;

/// Angular momentum (world frame) and kinetic energy of rotation of a box
/// of principal moments `inertia` in state `o`.
fn momentum_and_energy(o: &ObjectState, inertia: Vec3) -> (Vec3, f64) {
    let q = o.pose.orientation;
    let w_body = q.conjugate().rotate(o.angular_velocity_rad_s);
    let l_body = Vec3::new(
        inertia.x * w_body.x,
        inertia.y * w_body.y,
        inertia.z * w_body.z,
    );
    (q.rotate(l_body), 0.5 * w_body.dot(l_body))
}

/// A box of three different edges spun about a tilted axis with no gravity
/// and no ground (it precesses and nutates): over 2 s its angular
/// momentum, as a vector in the world, and its kinetic energy hold within
/// [`FreeBody::rotation`]; its centre does not move (1e-9 m).
pub fn torque_free_rotation(engine: &dyn Engine, spec: &KitSpec) {
    let scene = free_scene(SPUN);
    let inertia = scene.objects[0].principal_inertia();
    let mut sim = started(engine, spec, &scene);
    let first = object(sim.as_ref());
    let (l0, e0) = momentum_and_energy(&first, inertia);
    let steps = (2.0 / sim.timestep_s()).round() as u64;
    let (mut dl, mut de) = (0.0_f64, 0.0_f64);
    for _ in 0..steps {
        sim.step().unwrap();
        let o = object(sim.as_ref());
        assert!(
            o.pose.position_m.distance(first.pose.position_m) <= 1e-9,
            "{}: a box spinning without gravity moved its centre to {:?}",
            engine.name(),
            o.pose.position_m
        );
        let (l, e) = momentum_and_energy(&o, inertia);
        if spec.dynamics {
            dl = dl.max(l.distance(l0) / l0.norm());
            de = de.max((e - e0).abs() / e0);
        } else {
            dl = dl.max(o.pose.orientation.angle_to(first.pose.orientation));
        }
    }
    let [tl, te] = spec.free.rotation;
    report(engine, "torque_free_momentum_rel", dl, tl);
    report(engine, "torque_free_energy_rel", de, te);
    if !spec.dynamics {
        assert!(dl <= 1e-12, "{}: turned by {dl} rad", engine.name());
        return;
    }
    assert!(
        dl <= tl,
        "{}: the angular momentum of a torque-free box changed by {dl:e} of itself over 2 s (tolerance {tl:e})",
        engine.name()
    );
    assert!(
        de <= te,
        "{}: the kinetic energy of a torque-free box changed by {de:e} of itself over 2 s (tolerance {te:e})",
        engine.name()
    );
}

const DROPPED: &str = r#"
name = "dropped"
duration_s = 1.5
[ground]
height_m = 0.0
friction = 0.18
[[object]]
name = "cube"
shape = "box"
size_m = [0.1, 0.1, 0.1]
mass_kg = 0.37
position_m = [0.2, -0.1, 0.1]
friction = 0.18
[[track]]
role = "cube"
object = "cube"
"#;

/// The tossed cube's size and mass dropped flat from 5 cm onto the ground:
/// after 1.5 s it rests on its face at its rest height (within
/// [`FreeBody::rest_sink_m`] below it, 1 mm above), where it fell
/// ([`FreeBody::rest_drift_m`]), flat ([`FreeBody::rest_tilt_rad`]),
/// and still (1 cm/s).
pub fn drop_flat(engine: &dyn Engine, spec: &KitSpec) {
    let scene = free_scene(DROPPED);
    let mut sim = started(engine, spec, &scene);
    let start = scene.objects[0].pose;
    let steps = (1.5 / sim.timestep_s()).round() as u64;
    sim.step_n(steps).unwrap();
    let o = object(sim.as_ref());
    let p = o.pose.position_m;
    if !spec.dynamics {
        assert_eq!(o.pose, start, "{}: the dropped cube moved", engine.name());
        return;
    }
    let sink = 0.05 - p.z;
    let drift = ((p.x - start.position_m.x).powi(2) + (p.y - start.position_m.y).powi(2)).sqrt();
    let tilt = o.pose.orientation.angle_to(start.orientation);
    let speed = o.linear_velocity_m_s.norm();
    report(engine, "drop_flat_sink_m", sink, spec.free.rest_sink_m);
    report(engine, "drop_flat_drift_m", drift, spec.free.rest_drift_m);
    report(engine, "drop_flat_tilt_rad", tilt, spec.free.rest_tilt_rad);
    let name = engine.name();
    assert!(
        sink <= spec.free.rest_sink_m && sink >= -1e-3,
        "{name}: the dropped cube rests with its centre at {} m, {sink:e} m below its rest height 0.05 m",
        p.z
    );
    assert!(
        drift <= spec.free.rest_drift_m,
        "{name}: the cube dropped flat slid {drift:e} m"
    );
    assert!(
        tilt <= spec.free.rest_tilt_rad,
        "{name}: the cube dropped flat ends tilted by {tilt:e} rad"
    );
    assert!(
        speed <= 0.01,
        "{name}: the dropped cube still moves at {speed} m/s"
    );
}

const SLID: &str = r#"
name = "slid"
duration_s = 1.5
[ground]
height_m = 0.0
[[object]]
name = "cube"
shape = "box"
size_m = [0.1, 0.1, 0.1]
mass_kg = 0.37
position_m = [0.0, 0.0, 0.05]
friction = 0.2
linear_velocity_m_s = [1.0, 0.0, 0.0]
[[track]]
role = "cube"
object = "cube"
"#;

/// The tossed cube's size and mass set sliding on its face at 1 m/s over
/// the engine's own ground with friction 0.2 on the cube: it stops after
/// `v^2 / (2 mu g)`; the coefficient that distance shows must be
/// [`FreeBody::slide_friction_factor`] times 0.2 within 5 %: a friction
/// given for an object is the contact's (the ground is rougher), whatever
/// rule the engine combines two surfaces' coefficients with, unless the
/// spec says otherwise.
pub fn slide(engine: &dyn Engine, spec: &KitSpec) {
    let scene = free_scene(SLID);
    let mut sim = started(engine, spec, &scene);
    let steps = (1.5 / sim.timestep_s()).round() as u64;
    sim.step_n(steps).unwrap();
    let o = object(sim.as_ref());
    let start = scene.objects[0].pose.position_m;
    let d = o.pose.position_m.x - start.x;
    if !spec.dynamics {
        assert_eq!(d, 0.0, "{}: the cube moved", engine.name());
        return;
    }
    let g = -scene.gravity_m_s2.z;
    let mu = 1.0 / (2.0 * g * d);
    let want = 0.2 * spec.free.slide_friction_factor;
    report(engine, "slide_friction", mu, want);
    let name = engine.name();
    assert!(
        o.linear_velocity_m_s.norm() < 0.01,
        "{name}: the slid cube still moves at {} m/s after 1.5 s",
        o.linear_velocity_m_s.norm()
    );
    assert!(
        (mu / want - 1.0).abs() <= 0.05,
        "{name}: a cube with friction 0.2 slid {d} m from 1 m/s: a coefficient of {mu:.4}, not {want:.4} (within 5 %)"
    );
}
