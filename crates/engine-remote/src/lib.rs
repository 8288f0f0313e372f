//! Engines out of process: realitygap's engine interface
//! ([`realitygap_core::engine`]) spoken over a versioned JSON-lines
//! protocol (docs/engine-protocol.md) with an engine running as a child
//! process. The controller, the actuator stage, the measures and every
//! check stay in realitygap; the child only simulates.
//!
//! - [`wire`]: framing, numbers as IEEE bits, located reading of replies;
//! - [`child`]: one child process, its timeout and its standard error;
//! - [`model`]: the model description a child builds (bodies, servos,
//!   objects, tracked frames), resolved by core's shared planning;
//! - [`sim`]: [`Simulation`] over the protocol, one message a control
//!   period;
//! - [`registry`]: the built-in Python adapters (`mujoco4`, ...), their
//!   pinned environments, and a user's own engines (`engines.toml`);
//! - [`zygote`]: children forked from the engine's first process, which
//!   imported the engine once.
//!
//! A [`RemoteEngine`] asks its child `hello` once (name, version,
//! settings, parameters, command laws) and keeps that child idle for
//! `check_settings`; [`Engine::load_with`] takes the idle child (or starts
//! one), and a simulation that ends gives its child back, so a process
//! that runs one simulation after another starts the engine once; so does
//! a child that refused a model (an `error` reply). A child that breaks
//! the protocol (crashes, hangs, garbles) is stopped and never reused: a
//! crash ends one run, never a batch. A child it starts is forked from
//! the engine's zygote when the engine has one ([`zygote`]), so even the
//! processes of a batch import the engine once between them.

pub mod child;
pub mod model;
pub mod registry;
pub mod sim;
pub mod wire;
pub mod zygote;

use child::{Child, Failure, Launch};
use realitygap_core::engine::{
    CommandKind, CommandSupport, Engine, EngineError, EngineSettings, ModelVariation, SettingInfo,
    SettingsReader, Simulation,
};
use realitygap_core::params::{ParamKey, ParamSupport, PhysicalParams};
use realitygap_core::robot::RobotModel;
use realitygap_core::scene::Scene;
use serde_json::{json, Value};
use sim::{engine_error, Loaded, Reading, RemoteSimulation};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;
use wire::{Reply, PROTOCOL_VERSION};

/// The setting realitygap keeps for itself: the wait for each reply, s.
pub const TIMEOUT_KEY: &str = "timeout_s";

/// The wait for each reply when `timeout_s` is not set, s: long enough
/// for a slow engine's import and a long batch of steps.
pub const DEFAULT_TIMEOUT_S: f64 = 120.0;

const TIMEOUT_HELP: &str = "seconds to wait for each reply of the engine process (> 0); default 120; kept by realitygap, not sent to the engine";

/// The keys that realitygap writes into the model description itself, so
/// that every engine out of process honours them.
const DESCRIBED: [(ParamKey, &str); 7] = [
    (
        ParamKey::JointDamping,
        "the joint's damping in the model description",
    ),
    (
        ParamKey::JointFrictionloss,
        "the joint's frictionloss in the model description",
    ),
    (ParamKey::JointKv, "the servo's kv in the model description"),
    (
        ParamKey::JointForceLimit,
        "the servo's force_limit in the model description",
    ),
    (
        ParamKey::LinkMassScale,
        "the body's merged mass and inertia in the model description",
    ),
    (
        ParamKey::ObjectMass,
        "the object's mass and inertia in the model description",
    ),
    (
        ParamKey::ObjectFriction,
        "the object's friction in the model description",
    ),
];

/// What an engine child said of itself in `hello`.
#[derive(Debug, Clone)]
pub struct Hello {
    /// Its engine name.
    pub engine: String,
    /// Its library's version.
    pub version: String,
    /// Its default timestep, s.
    pub default_timestep_s: f64,
    /// Its settings (with `timeout_s` added).
    pub settings: Vec<SettingInfo>,
    /// The parameters it maps itself, and the ones described for it.
    pub params: Vec<ParamSupport>,
    /// Its servo laws.
    pub commands: Vec<CommandSupport>,
    /// Whether it takes `run` in columns (a replay's schedule as arrays,
    /// its readings back as one vector), which the SDK's adapters do.
    pub columns: bool,
}

fn leak(s: &str) -> &'static str {
    Box::leak(s.to_string().into_boxed_str())
}

/// The parameter key of a pattern as an adapter writes it
/// (`joints.*.armature` or `joints.<joint>.armature`).
fn param_key(pattern: &str) -> Option<ParamKey> {
    let norm = |p: &str| -> String {
        p.split('.')
            .map(|part| {
                if part.starts_with('<') || part == "*" {
                    "*"
                } else {
                    part
                }
            })
            .collect::<Vec<_>>()
            .join(".")
    };
    let want = norm(pattern);
    ParamKey::ALL
        .into_iter()
        .find(|k| norm(k.pattern()) == want)
}

impl Hello {
    fn parse(reply: &Reply) -> Result<Hello, String> {
        let protocol = reply.number("protocol")?;
        if protocol != PROTOCOL_VERSION as f64 {
            return Err(format!(
                "the engine speaks protocol {protocol}, realitygap speaks {PROTOCOL_VERSION}"
            ));
        }
        let list = |key: &str, a: &str, b: &str| -> Result<Vec<(String, String)>, String> {
            reply
                .array(key)?
                .iter()
                .map(|v| {
                    let pair = (v.get(a).and_then(Value::as_str), v.get(b).and_then(Value::as_str));
                    match pair {
                        (Some(x), Some(y)) => Ok((x.to_string(), y.to_string())),
                        _ => Err(format!(
                            "the reply to \"hello\": each of \"{key}\" needs text \"{a}\" and \"{b}\""
                        )),
                    }
                })
                .collect()
        };
        let mut settings: Vec<SettingInfo> = list("settings", "key", "help")?
            .into_iter()
            .map(|(k, h)| SettingInfo {
                key: leak(&k),
                help: leak(&h),
            })
            .collect();
        settings.push(SettingInfo {
            key: TIMEOUT_KEY,
            help: TIMEOUT_HELP,
        });
        let mut params: Vec<ParamSupport> = DESCRIBED
            .iter()
            .map(|&(key, mapping)| ParamSupport { key, mapping })
            .collect();
        for (pattern, mapping) in list("params", "key", "mapping")? {
            let key = param_key(&pattern).ok_or_else(|| {
                format!("the reply to \"hello\": \"{pattern}\" is not a parameter key")
            })?;
            params.push(ParamSupport {
                key,
                mapping: leak(&mapping),
            });
        }
        let commands = list("commands", "kind", "mechanism")?
            .into_iter()
            .map(|(kind, mechanism)| {
                let kind = match kind.as_str() {
                    "velocity" => CommandKind::Velocity,
                    "position" => CommandKind::Position,
                    "effort" => CommandKind::Effort,
                    other => {
                        return Err(format!(
                            "the reply to \"hello\": \"{other}\" is not a command kind"
                        ))
                    }
                };
                Ok(CommandSupport {
                    kind,
                    mechanism: leak(&mechanism),
                })
            })
            .collect::<Result<Vec<_>, String>>()?;
        let default_timestep_s = reply.number("default_timestep_s")?;
        if !(default_timestep_s.is_finite() && default_timestep_s > 0.0) {
            return Err(format!(
                "the reply to \"hello\": default_timestep_s {default_timestep_s} is not a positive time"
            ));
        }
        Ok(Hello {
            engine: reply.text("engine")?.to_string(),
            version: reply.text("version")?.to_string(),
            default_timestep_s,
            settings,
            params,
            commands,
            columns: reply.value("columns").and_then(Value::as_bool) == Some(true),
        })
    }
}

/// An engine that runs as a child process (clones share its `hello` and
/// its settings child).
#[derive(Clone)]
pub struct RemoteEngine {
    inner: Arc<Inner>,
}

struct Inner {
    name: &'static str,
    launch: Launch,
    /// What stops the engine from running at all (its environment is not
    /// installed), with the line that installs it.
    unavailable: Option<String>,
    hello: OnceLock<Result<Hello, String>>,
    /// The idle children: the one `hello` started, and those whose
    /// simulation ended (at most [`sim::MAX_IDLE`]); `check_settings` asks
    /// the newest, and `load` takes it.
    control: sim::IdleSlot,
}

impl RemoteEngine {
    /// The engine `name`, started with `launch`.
    pub fn new(name: &str, launch: Launch) -> RemoteEngine {
        RemoteEngine::with(name, launch, None)
    }

    fn with(name: &str, launch: Launch, unavailable: Option<String>) -> RemoteEngine {
        RemoteEngine {
            inner: Arc::new(Inner {
                name: leak(name),
                launch,
                unavailable,
                hello: OnceLock::new(),
                control: Arc::new(Mutex::new(Vec::new())),
            }),
        }
    }

    /// An engine that cannot start, for `reason` (every load says it).
    pub fn unavailable(name: &str, reason: String) -> RemoteEngine {
        let launch = Launch {
            command: Vec::new(),
            env: Vec::new(),
        };
        RemoteEngine::with(name, launch, Some(reason))
    }

    /// Why the engine cannot start at all, when it cannot.
    pub fn unavailable_reason(&self) -> Option<&str> {
        self.inner.unavailable.as_deref()
    }

    /// How the engine's process is started.
    pub fn launch(&self) -> &Launch {
        &self.inner.launch
    }

    fn load_error(&self, message: String) -> EngineError {
        EngineError::Load {
            engine: self.inner.name.to_string(),
            message,
        }
    }

    /// Starts a child and greets it; the message says why it cannot.
    fn start(&self, timeout: Duration) -> Result<(Child, Hello), String> {
        if let Some(reason) = &self.inner.unavailable {
            return Err(reason.clone());
        }
        let mut child = Child::spawn(&self.inner.launch, timeout)?;
        let fields = child
            .call(&json!({"op": "hello", "protocol": PROTOCOL_VERSION}))
            .map_err(|f| match f {
                Failure::Broken(m) => m,
                Failure::Engine { message, .. } => format!("\"hello\" refused: {message}"),
            })?;
        let hello = Hello::parse(&Reply {
            op: "hello",
            fields: &fields,
        })?;
        if hello.engine != self.inner.name {
            return Err(format!(
                "the process started for engine \"{}\" says it is \"{}\"",
                self.inner.name, hello.engine
            ));
        }
        Ok((child, hello))
    }

    /// The engine's `hello`, asked once (the child is kept for
    /// `check_settings`).
    pub fn hello(&self) -> Result<&Hello, String> {
        self.inner
            .hello
            .get_or_init(|| {
                let (child, hello) = self.start(Duration::from_secs_f64(DEFAULT_TIMEOUT_S))?;
                sim::give_back(&self.inner.control, child);
                Ok(hello)
            })
            .as_ref()
            .map_err(Clone::clone)
    }

    /// The reply timeout of `settings` and the settings the child gets.
    fn split_timeout(
        &self,
        settings: &EngineSettings,
    ) -> Result<(Duration, EngineSettings), EngineError> {
        let mut rest = settings.clone();
        let timeout = match rest.remove(TIMEOUT_KEY) {
            None => DEFAULT_TIMEOUT_S,
            Some(v) => match v.as_f64() {
                Some(t) if t.is_finite() && t > 0.0 => t,
                _ => {
                    return Err(EngineError::Setting {
                        engine: self.inner.name.to_string(),
                        key: TIMEOUT_KEY.into(),
                        message: format!("must be a positive number of seconds, found {v}"),
                    })
                }
            },
        };
        Ok((Duration::from_secs_f64(timeout), rest))
    }
}

impl Engine for RemoteEngine {
    fn name(&self) -> &'static str {
        self.inner.name
    }

    fn version(&self) -> String {
        match self.hello() {
            Ok(h) => h.version.clone(),
            Err(e) => format!("unavailable: {e}"),
        }
    }

    fn default_timestep_s(&self) -> f64 {
        self.hello()
            .map(|h| h.default_timestep_s)
            .unwrap_or(f64::NAN)
    }

    fn settings_help(&self) -> Vec<SettingInfo> {
        self.hello().map(|h| h.settings.clone()).unwrap_or_default()
    }

    fn check_settings(&self, settings: &EngineSettings) -> Result<f64, EngineError> {
        let hello = self.hello().map_err(|m| self.load_error(m))?;
        // Unknown keys are refused here, naming every accepted key
        // (`timeout_s` too), in the linked engines' words.
        SettingsReader::new(self.inner.name, settings, &hello.settings)?;
        let (timeout, rest) = self.split_timeout(settings)?;
        let mut control = self.inner.control.lock().unwrap_or_else(|e| e.into_inner());
        if control.is_empty() {
            let (child, _) = self.start(timeout).map_err(|m| self.load_error(m))?;
            control.push(child);
        }
        let child = control.last_mut().expect("started");
        child.set_timeout(timeout);
        let result =
            child.call(&json!({"op": "check_settings", "settings": model::settings_json(&rest)}));
        let fields = match result {
            Ok(f) => f,
            Err(f) => {
                if matches!(f, Failure::Broken(_)) {
                    control.pop();
                }
                return Err(engine_error(self.inner.name, f, |m| self.load_error(m)));
            }
        };
        let reply = Reply {
            op: "check_settings",
            fields: &fields,
        };
        let dt = reply
            .vector("timestep_s", Some(1))
            .map_err(|m| self.load_error(m))?[0];
        if dt <= 0.0 {
            return Err(self.load_error(format!("the engine's timestep {dt} s is not positive")));
        }
        Ok(dt)
    }

    fn param_support(&self) -> Vec<ParamSupport> {
        self.hello().map(|h| h.params.clone()).unwrap_or_default()
    }

    fn command_support(&self) -> Vec<CommandSupport> {
        self.hello().map(|h| h.commands.clone()).unwrap_or_default()
    }

    fn load_with(
        &self,
        scene: &Scene,
        robot: &RobotModel,
        settings: &EngineSettings,
        variation: &ModelVariation,
        params: &PhysicalParams,
    ) -> Result<Box<dyn Simulation>, EngineError> {
        variation.check().map_err(|m| self.load_error(m))?;
        params.check_fixed_base_masses(self.inner.name, scene, robot)?;
        model::check_held_joint_params(self.inner.name, scene, robot, params)?;
        let (timeout, rest) = self.split_timeout(settings)?;
        let timestep_s = self.check_settings(settings)?;
        let columns = self.hello().is_ok_and(|h| h.columns);
        let description = model::describe(scene, robot, &rest, variation, params)
            .map_err(|m| self.load_error(m))?;
        let idle = self
            .inner
            .control
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .pop();
        let mut child = match idle {
            Some(mut child) => {
                child.set_timeout(timeout);
                child
            }
            None => self.start(timeout).map_err(|m| self.load_error(m))?.0,
        };
        let fields = match child.call(&json!({"op": "load", "model": description})) {
            Ok(fields) => fields,
            Err(f) => {
                // A refused model leaves a healthy child: it waits for the
                // next load (starting one costs seconds: Newton 3.3 s).
                if matches!(f, Failure::Engine { .. }) {
                    sim::give_back(&self.inner.control, child);
                }
                return Err(engine_error(self.inner.name, f, |m| self.load_error(m)));
            }
        };
        let reply = Reply {
            op: "load",
            fields: &fields,
        };
        let reading = Reading::parse(&reply, scene.actuators.len(), scene.tracked.len())
            .map_err(|m| self.load_error(m))?;
        let issues = sim::stability_issues(&reply).map_err(|m| self.load_error(m))?;
        Ok(Box::new(RemoteSimulation::new(
            self.inner.name,
            scene,
            child,
            Arc::clone(&self.inner.control),
            timestep_s,
            Loaded {
                reading,
                issues,
                columns,
            },
        )))
    }
}
