//! A simulation in an engine child: [`Simulation`] over the protocol.
//!
//! One reply per control period: commands set between steps are held here
//! and travel with the next `step`, whose reply carries the reading (time,
//! joint angles and velocities, tracked poses) that the controller then
//! reads from here without another message.

use crate::child::{Child, Failure};
use crate::wire::{bits, Reply};
use realitygap_core::engine::{
    check_servo_commands, CommandKind, EngineError, NativeState, ObjectState, Segment,
    SegmentReading, ServoCommand, SimState, Simulation, StabilityIssue,
};
use realitygap_core::pose::{Pose, Quat, Vec3};
use realitygap_core::scene::Scene;
use serde_json::{json, Map, Value};
use std::cell::RefCell;
use std::sync::{Arc, Mutex};

/// Where a simulation's child goes back to when the simulation ends: its
/// engine's idle children, for the next `check_settings` or `load` (a
/// second `load` replaces the child's simulation), so that a process
/// running one simulation after another starts the engine once, and one
/// running a few side by side (a state handed from one simulation to
/// another, a reference beside a candidate) starts it once per
/// simulation alive at the same time, not once per simulation.
pub(crate) type IdleSlot = Arc<Mutex<Vec<Child>>>;

/// The most idle children an engine keeps (each holds its engine's
/// libraries and last model: a Newton child about 420 MB); a child that
/// ends its simulation when this many wait is stopped.
pub(crate) const MAX_IDLE: usize = 3;

/// Puts `child` back into `slot` for the next `check_settings` or `load`,
/// unless it is broken (it is dropped, and the next request starts a new
/// one) or the slot already holds [`MAX_IDLE`] children.
pub(crate) fn give_back(slot: &IdleSlot, child: Child) {
    if child.is_broken() {
        return;
    }
    let mut idle = slot.lock().unwrap_or_else(|e| e.into_inner());
    if idle.len() < MAX_IDLE {
        idle.push(child);
    }
}

/// Turns a failed request into the engine error of its kind; a broken
/// child is `broken(message)`.
pub(crate) fn engine_error(
    engine: &str,
    failure: Failure,
    broken: impl FnOnce(String) -> EngineError,
) -> EngineError {
    let engine_s = engine.to_string();
    match failure {
        Failure::Broken(message) => broken(message),
        Failure::Engine {
            kind,
            message,
            key,
            t_s,
        } => match kind.as_str() {
            "setting" => EngineError::Setting {
                engine: engine_s,
                key: key.unwrap_or_default(),
                message,
            },
            "param" => EngineError::Param {
                engine: engine_s,
                key: key.unwrap_or_default(),
                message,
            },
            "load" => EngineError::Load {
                engine: engine_s,
                message,
            },
            "state" => EngineError::State {
                engine: engine_s,
                message,
            },
            "unstable" => match (broken(message), t_s) {
                (
                    EngineError::Unstable {
                        engine, message, ..
                    },
                    Some(t),
                ) if t.is_finite() => EngineError::Unstable {
                    engine,
                    t_s: t,
                    message,
                },
                (e, _) => e,
            },
            _ => EngineError::Usage {
                engine: engine_s,
                message,
            },
        },
    }
}

fn kind_name(kind: CommandKind) -> &'static str {
    match kind {
        CommandKind::Velocity => "velocity",
        CommandKind::Position => "position",
        CommandKind::Effort => "effort",
    }
}

fn commands_json(commands: &[ServoCommand]) -> Value {
    let (kinds, values) = commands_json_parts(commands);
    json!({"kinds": kinds, "values": bits(&values)})
}

/// The kinds and values of `commands`, as they travel.
fn commands_json_parts(commands: &[ServoCommand]) -> (Vec<&'static str>, Vec<f64>) {
    (
        commands.iter().map(|c| kind_name(c.kind)).collect(),
        commands.iter().map(|c| c.value).collect(),
    )
}

/// A schedule's change of commands: its segment, kinds and values.
struct Change {
    segment: usize,
    kinds: Vec<&'static str>,
    values: Vec<f64>,
}

/// A `run` request as segments (protocol 1's first form): `changes` are
/// the segments that set commands, with their kinds and values.
fn segments_request(segments: &[Segment], changes: &[Change]) -> Value {
    let mut changes = changes.iter().peekable();
    let wire: Vec<Value> = segments
        .iter()
        .enumerate()
        .map(|(i, segment)| {
            let mut w = json!({"read": segment.read, "steps": segment.steps});
            if let Some(c) = changes.next_if(|c| c.segment == i) {
                w["commands"] = json!({"kinds": c.kinds, "values": bits(&c.values)});
            }
            w
        })
        .collect();
    json!({"op": "run", "segments": wire})
}

/// The same `run` request in columns: per segment its steps and whether
/// it reads; per change of commands its segment, its kinds (an index into
/// the distinct kinds sent, `laws`) and its values (one vector for all).
fn columns_request(segments: &[Segment], changes: &[Change]) -> Value {
    let mut laws: Vec<&Vec<&str>> = Vec::new();
    let mut law = Vec::with_capacity(changes.len());
    let mut values = Vec::new();
    for c in changes {
        let index = laws.iter().position(|k| **k == c.kinds).unwrap_or_else(|| {
            laws.push(&c.kinds);
            laws.len() - 1
        });
        law.push(index);
        values.extend_from_slice(&c.values);
    }
    let steps: Vec<u64> = segments.iter().map(|s| s.steps).collect();
    let read: String = segments
        .iter()
        .map(|s| if s.read { '1' } else { '0' })
        .collect();
    let at: Vec<usize> = changes.iter().map(|c| c.segment).collect();
    json!({"op": "run", "columns": {
        "steps": steps, "read": read, "at": at, "laws": laws, "law": law, "values": bits(&values),
    }})
}

/// The readings of a `run` reply in columns: one vector of rows `t, q,
/// qd, poses`.
fn reading_rows(reply: &Reply, joints: usize, tracked: usize) -> Result<Vec<Reading>, String> {
    let width = 1 + 2 * joints + 7 * tracked;
    let flat = reply.vector("readings", None)?;
    if flat.len() % width != 0 {
        return Err(format!(
            "the reply to \"run\": field \"readings\" has {} numbers, not a whole number of readings of {width} (t, {joints} q, {joints} qd, {tracked} poses)",
            flat.len()
        ));
    }
    Ok(flat
        .chunks_exact(width)
        .map(|row| Reading {
            t: row[0],
            q: row[1..1 + joints].to_vec(),
            qd: row[1 + joints..1 + 2 * joints].to_vec(),
            poses: row[1 + 2 * joints..].chunks(7).map(pose_of).collect(),
        })
        .collect())
}

/// The readings of a `run` reply as segments: one object per reading.
fn reading_objects(reply: &Reply, joints: usize, tracked: usize) -> Result<Vec<Reading>, String> {
    reply
        .array("readings")?
        .iter()
        .map(|v| {
            let fields = v
                .as_object()
                .ok_or("the reply to \"run\": a reading is not an object")?;
            Reading::of(&Reply { op: "run", fields }, joints, tracked)
        })
        .collect()
}

fn pose_of(v: &[f64]) -> Pose {
    Pose::new(
        Vec3::new(v[0], v[1], v[2]),
        Quat {
            w: v[3],
            x: v[4],
            y: v[5],
            z: v[6],
        },
    )
}

/// What the controller reads after a step.
#[derive(Debug, Clone)]
pub(crate) struct Reading {
    pub t: f64,
    pub q: Vec<f64>,
    pub qd: Vec<f64>,
    pub poses: Vec<Pose>,
}

impl Reading {
    /// The reading in `reply`'s field `state`.
    pub fn parse(reply: &Reply, joints: usize, tracked: usize) -> Result<Reading, String> {
        Reading::of(&reply.object("state")?, joints, tracked)
    }

    /// The reading that is `s`.
    pub fn of(s: &Reply, joints: usize, tracked: usize) -> Result<Reading, String> {
        let t = s.vector("t", Some(1))?[0];
        let q = s.vector("q", Some(joints))?;
        let qd = s.vector("qd", Some(joints))?;
        let flat = s.vector("poses", Some(7 * tracked))?;
        Ok(Reading {
            t,
            q,
            qd,
            poses: flat.chunks(7).map(pose_of).collect(),
        })
    }
}

/// The stability issues of a `load` reply.
pub(crate) fn stability_issues(reply: &Reply) -> Result<Vec<StabilityIssue>, String> {
    let Some(list) = reply.value("stability_issues") else {
        return Ok(Vec::new());
    };
    let list = list
        .as_array()
        .ok_or("the reply to \"load\": stability_issues is not an array")?;
    list.iter()
        .map(|v| {
            let fields = v
                .as_object()
                .ok_or("the reply to \"load\": a stability issue is not an object")?;
            let r = Reply { op: "load", fields };
            Ok(StabilityIssue {
                joint: r.value("joint").and_then(Value::as_str).map(str::to_string),
                quantity: r.text("quantity")?.to_string(),
                value: r.number("value")?,
                bound: r.number("bound")?,
                message: r.text("message")?.to_string(),
            })
        })
        .collect()
}

/// What a child's `load` gave: its first reading and stability issues,
/// and whether it takes `run` in columns (its `hello`).
pub(crate) struct Loaded {
    pub reading: Reading,
    pub issues: Vec<StabilityIssue>,
    pub columns: bool,
}

/// A running simulation in an engine child.
pub struct RemoteSimulation {
    engine: &'static str,
    scene: Scene,
    /// The child (taken only when the simulation ends).
    child: RefCell<Option<Child>>,
    idle: IdleSlot,
    timestep_s: f64,
    reading: Reading,
    /// The commands in force (velocity targets 0 at the start).
    commands: Vec<ServoCommand>,
    /// Whether `commands` changed since the child last had them.
    pending: bool,
    issues: Vec<StabilityIssue>,
    /// Whether the child takes `run` in columns.
    columns: bool,
}

impl RemoteSimulation {
    pub(crate) fn new(
        engine: &'static str,
        scene: &Scene,
        child: Child,
        idle: IdleSlot,
        timestep_s: f64,
        loaded: Loaded,
    ) -> RemoteSimulation {
        let Loaded {
            reading,
            issues,
            columns,
        } = loaded;
        RemoteSimulation {
            engine,
            commands: vec![ServoCommand::velocity(0.0); scene.actuators.len()],
            scene: scene.clone(),
            child: RefCell::new(Some(child)),
            idle,
            timestep_s,
            reading,
            pending: false,
            issues,
            columns,
        }
    }

    fn unstable(&self, message: String) -> EngineError {
        EngineError::Unstable {
            engine: self.engine.to_string(),
            t_s: self.reading.t,
            message,
        }
    }

    /// Sends `request` and returns its reply's fields; a broken child is
    /// an unstable run at the current time.
    fn call(&self, request: Value) -> Result<Map<String, Value>, EngineError> {
        let result = self
            .child
            .borrow_mut()
            .as_mut()
            .expect("the child is there until the simulation ends")
            .call(&request);
        result.map_err(|f| engine_error(self.engine, f, |m| self.unstable(m)))
    }

    /// Sends a request whose reply is a reading, and keeps it.
    fn call_reading(&mut self, request: Value) -> Result<(), EngineError> {
        let op = request["op"].as_str().unwrap_or("?").to_string();
        let fields = self.call(request)?;
        let reply = Reply {
            op: &op,
            fields: &fields,
        };
        let reading = Reading::parse(&reply, self.scene.actuators.len(), self.scene.tracked.len())
            .map_err(|m| self.unstable(m))?;
        self.reading = reading;
        Ok(())
    }

    fn usage(&self, message: String) -> EngineError {
        EngineError::Usage {
            engine: self.engine.to_string(),
            message,
        }
    }
}

impl Drop for RemoteSimulation {
    fn drop(&mut self) {
        if let Some(child) = self.child.get_mut().take() {
            give_back(&self.idle, child);
        }
    }
}

impl Simulation for RemoteSimulation {
    fn stability_issues(&self) -> Vec<StabilityIssue> {
        self.issues.clone()
    }

    fn timestep_s(&self) -> f64 {
        self.timestep_s
    }

    fn time_s(&self) -> f64 {
        self.reading.t
    }

    fn joint_count(&self) -> usize {
        self.scene.actuators.len()
    }

    fn tracked_count(&self) -> usize {
        self.scene.tracked.len()
    }

    fn set_joint_angles_rad(&mut self, rad: &[f64]) -> Result<(), EngineError> {
        if rad.len() != self.joint_count() {
            return Err(self.usage(format!(
                "{} joint angles for {} controlled joints",
                rad.len(),
                self.joint_count()
            )));
        }
        if let Some(i) = rad.iter().position(|a| !a.is_finite()) {
            return Err(self.usage(format!(
                "the angle of joint \"{}\" is {} (not finite)",
                self.scene.actuators[i].joint, rad[i]
            )));
        }
        self.call_reading(json!({"op": "set_joint_angles", "q": bits(rad)}))
    }

    fn set_joint_velocity_targets(&mut self, rad_s: &[f64]) {
        // A vector of the wrong length (the trait gives no error to
        // return) sets the joints it reaches; the others keep their
        // velocity target, or get 0.
        let commands: Vec<ServoCommand> = self
            .commands
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let kept = if c.kind == CommandKind::Velocity {
                    c.value
                } else {
                    0.0
                };
                ServoCommand::velocity(rad_s.get(i).copied().unwrap_or(kept))
            })
            .collect();
        if commands != self.commands {
            self.commands = commands;
            self.pending = true;
        }
    }

    fn set_joint_commands(&mut self, commands: &[ServoCommand]) -> Result<(), EngineError> {
        check_servo_commands(self.engine, &self.scene, commands)?;
        if commands != self.commands.as_slice() {
            self.commands = commands.to_vec();
            self.pending = true;
        }
        Ok(())
    }

    fn step(&mut self) -> Result<(), EngineError> {
        self.step_n(1)
    }

    fn step_n(&mut self, n: u64) -> Result<(), EngineError> {
        if n == 0 {
            return Ok(());
        }
        let mut request = json!({"op": "step", "n": n});
        if self.pending {
            request["commands"] = commands_json(&self.commands);
        }
        self.call_reading(request)?;
        self.pending = false;
        Ok(())
    }

    fn run_segments(
        &mut self,
        segments: &[Segment],
        readings: &mut Vec<SegmentReading>,
    ) -> Result<(), EngineError> {
        // One message for the whole schedule; commands set before it
        // travel with its first segment.
        let mut commands = self.commands.clone();
        let mut pending = self.pending;
        let mut changes = Vec::new();
        for (i, segment) in segments.iter().enumerate() {
            if let Some(c) = &segment.commands {
                check_servo_commands(self.engine, &self.scene, c)?;
                commands.clone_from(c);
                pending = true;
            }
            if pending {
                let (kinds, values) = commands_json_parts(&commands);
                changes.push(Change {
                    segment: i,
                    kinds,
                    values,
                });
                pending = false;
            }
        }
        let request = if self.columns {
            columns_request(segments, &changes)
        } else {
            segments_request(segments, &changes)
        };
        let fields = self.call(request)?;
        self.commands = commands;
        self.pending = false;
        let reply = Reply {
            op: "run",
            fields: &fields,
        };
        let (joints, tracked) = (self.joint_count(), self.tracked_count());
        let taken = if self.columns {
            reading_rows(&reply, joints, tracked)
        } else {
            reading_objects(&reply, joints, tracked)
        }
        .map_err(|m| self.unstable(m))?;
        if let Some(last) = taken.last() {
            self.reading.t = last.t;
        }
        readings.extend(taken.into_iter().map(|r| SegmentReading {
            angles_rad: r.q,
            velocities_rad_s: r.qd,
            poses: r.poses,
        }));
        if let Some(error) = reply.value("error") {
            let failure = Failure::from_error(error, "unstable");
            return Err(engine_error(self.engine, failure, |m| self.unstable(m)));
        }
        self.reading = Reading::parse(&reply, joints, tracked).map_err(|m| self.unstable(m))?;
        Ok(())
    }

    fn joint_angles_rad(&self, out: &mut [f64]) {
        out.copy_from_slice(&self.reading.q);
    }

    fn joint_velocities_rad_s(&self, out: &mut [f64]) -> Result<(), EngineError> {
        out.copy_from_slice(&self.reading.qd);
        Ok(())
    }

    fn tracked_poses(&self, out: &mut [Pose]) {
        out.copy_from_slice(&self.reading.poses);
    }

    fn state(&self) -> Result<SimState, EngineError> {
        let fields = self.call(json!({"op": "get_state"}))?;
        let reply = Reply {
            op: "get_state",
            fields: &fields,
        };
        let joints = self.joint_count();
        let parse = || -> Result<SimState, String> {
            let objects = reply.array("objects")?;
            if objects.len() != self.scene.objects.len() {
                return Err(format!(
                    "the reply to \"get_state\" has {} objects, the scene {}",
                    objects.len(),
                    self.scene.objects.len()
                ));
            }
            let objects = objects
                .iter()
                .zip(&self.scene.objects)
                .map(|(v, o)| {
                    let fields = v
                        .as_object()
                        .ok_or("the reply to \"get_state\": an object is not an object")?;
                    let r = Reply {
                        op: "get_state",
                        fields,
                    };
                    let three = |k| r.vector(k, Some(3)).map(|v| Vec3::new(v[0], v[1], v[2]));
                    Ok(ObjectState {
                        name: o.name.clone(),
                        pose: pose_of(&r.vector("pose", Some(7))?),
                        linear_velocity_m_s: three("v")?,
                        angular_velocity_rad_s: three("w")?,
                    })
                })
                .collect::<Result<Vec<_>, String>>()?;
            let native = match reply.value("native") {
                Some(_) => Some(NativeState {
                    engine: self.engine.to_string(),
                    data: reply.vector("native", None)?,
                }),
                None => None,
            };
            let all_velocity = self
                .commands
                .iter()
                .all(|c| c.kind == CommandKind::Velocity);
            Ok(SimState {
                time_s: reply.vector("t", Some(1))?[0],
                joint_angles_rad: reply.vector("q", Some(joints))?,
                joint_velocities_rad_s: reply.vector("qd", Some(joints))?,
                joint_velocity_targets_rad_s: self
                    .commands
                    .iter()
                    .map(|c| {
                        if c.kind == CommandKind::Velocity {
                            c.value
                        } else {
                            0.0
                        }
                    })
                    .collect(),
                servo_commands: if all_velocity {
                    Vec::new()
                } else {
                    self.commands.clone()
                },
                objects,
                native,
            })
        };
        parse().map_err(|m| self.unstable(m))
    }

    fn set_state(&mut self, state: &SimState) -> Result<(), EngineError> {
        let names: Vec<&str> = self.scene.objects.iter().map(|o| o.name.as_str()).collect();
        state
            .check(self.joint_count(), &names)
            .map_err(|message| EngineError::State {
                engine: self.engine.to_string(),
                message,
            })?;
        let commands: Vec<ServoCommand> = if state.servo_commands.is_empty() {
            state
                .joint_velocity_targets_rad_s
                .iter()
                .map(|v| ServoCommand::velocity(*v))
                .collect()
        } else {
            state.servo_commands.clone()
        };
        let objects: Vec<Value> = state
            .objects
            .iter()
            .map(|o| {
                let (p, q) = (o.pose.position_m, o.pose.orientation);
                let (v, w) = (o.linear_velocity_m_s, o.angular_velocity_rad_s);
                json!({
                    "name": o.name,
                    "pose": bits(&[p.x, p.y, p.z, q.w, q.x, q.y, q.z]),
                    "v": bits(&[v.x, v.y, v.z]),
                    "w": bits(&[w.x, w.y, w.z]),
                })
            })
            .collect();
        let native = state
            .native
            .as_ref()
            .filter(|n| n.engine == self.engine)
            .map(|n| Value::String(bits(&n.data)))
            .unwrap_or(Value::Null);
        self.call_reading(json!({
            "op": "set_state",
            "t": bits(&[state.time_s]),
            "q": bits(&state.joint_angles_rad),
            "qd": bits(&state.joint_velocities_rad_s),
            "objects": objects,
            "native": native,
            "commands": commands_json(&commands),
        }))?;
        self.commands = commands;
        self.pending = false;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::floats;

    fn changes() -> Vec<Change> {
        [
            (0, ["velocity", "velocity"], [0.5, -0.5]),
            (2, ["position", "velocity"], [0.1, 0.0]),
            (3, ["velocity", "velocity"], [1.0, 2.0]),
        ]
        .into_iter()
        .map(|(segment, kinds, values)| Change {
            segment,
            kinds: kinds.to_vec(),
            values: values.to_vec(),
        })
        .collect()
    }

    fn segments() -> Vec<Segment> {
        [(true, 5), (false, 3), (true, 0), (true, 2)]
            .into_iter()
            .map(|(read, steps)| Segment {
                read,
                commands: None,
                steps,
            })
            .collect()
    }

    #[test]
    fn a_schedule_travels_in_columns_with_each_law_once() {
        let r = columns_request(&segments(), &changes());
        let c = &r["columns"];
        assert_eq!(r["op"], "run");
        assert_eq!(c["steps"], json!([5, 3, 0, 2]));
        assert_eq!(c["read"], "1011");
        assert_eq!(c["at"], json!([0, 2, 3]));
        assert_eq!(
            c["laws"],
            json!([["velocity", "velocity"], ["position", "velocity"]])
        );
        assert_eq!(c["law"], json!([0, 1, 0]));
        assert_eq!(
            floats(c["values"].as_str().unwrap()).unwrap(),
            [0.5, -0.5, 0.1, 0.0, 1.0, 2.0]
        );
        // The same schedule as segments: commands where they change.
        let s = segments_request(&segments(), &changes());
        let w = s["segments"].as_array().unwrap();
        assert_eq!(w.len(), 4);
        assert!(w[1].get("commands").is_none());
        assert_eq!(w[2]["commands"]["kinds"], json!(["position", "velocity"]));
        assert_eq!(w[3]["steps"], 2);
    }

    #[test]
    fn readings_in_columns_are_rows_of_a_width() {
        // 2 joints, 1 tracked frame: rows of 1 + 2 + 2 + 7 numbers.
        let row = |t: f64| [t, 1.0, 2.0, 3.0, 4.0, 0.1, 0.2, 0.3, 1.0, 0.0, 0.0, 0.0];
        let flat: Vec<f64> = row(0.0).into_iter().chain(row(0.5)).collect();
        let fields = json!({"readings": bits(&flat)});
        let reply = Reply {
            op: "run",
            fields: fields.as_object().unwrap(),
        };
        let rows = reading_rows(&reply, 2, 1).unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!(
            (rows[1].t, &rows[1].q, &rows[1].qd),
            (0.5, &vec![1.0, 2.0], &vec![3.0, 4.0])
        );
        assert_eq!(rows[1].poses[0].position_m.z, 0.3);
        let short = json!({"readings": bits(&flat[..20])});
        let reply = Reply {
            op: "run",
            fields: short.as_object().unwrap(),
        };
        assert_eq!(
            reading_rows(&reply, 2, 1).unwrap_err(),
            "the reply to \"run\": field \"readings\" has 20 numbers, not a whole number of readings of 12 (t, 2 q, 2 qd, 1 poses)"
        );
        let nan = json!({"readings": bits(&[f64::NAN; 12])});
        let reply = Reply {
            op: "run",
            fields: nan.as_object().unwrap(),
        };
        assert!(reading_rows(&reply, 2, 1)
            .unwrap_err()
            .contains("readings[0] is NaN"));
    }
}
