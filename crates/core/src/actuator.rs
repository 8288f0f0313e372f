//! The actuator stage: between the command in force and the target an
//! engine's servo tracks, the same model for every engine (typed
//! parameters `[actuator]`, [`crate::params::ActuatorParams`]).
//!
//! A real arm's joint does not take its velocity command at once: its own
//! firmware loop responds with a lag, an overshoot, limits and a deadband.
//! The stage gives any engine's servo that response, so that an engine can
//! have a stiff servo while the stage gives the real arm's dynamics:
//!
//! ```text
//! command in force (after the controller's delay and acceleration limit)
//!   -> deadband (velocity commands below it are 0)
//!   -> second-order response: y'' = w^2 (u - y) - 2 zeta w y'
//!   -> velocity limit (of y for velocity commands, of y's rate for positions)
//!   -> the servo's target
//! ```
//!
//! The response is integrated by semi-implicit Euler in substeps of at most
//! [`MAX_SUBSTEP_S`]; at the natural frequencies of robot joints (20-100
//! rad/s) that is within a fraction of a percent of the exact response.
//! A far stiffer stage takes shorter substeps with its damping implicit,
//! so that no accepted value makes the targets non-finite.

use crate::params::PhysicalParams;

/// The longest integration substep of the response, s.
pub const MAX_SUBSTEP_S: f64 = 5e-4;

/// The largest `w dt` (and half the largest `2 zeta w dt`) of a substep
/// integrated explicitly; a stiffer stage (a natural frequency or damping
/// far beyond a robot joint's, up to core's `PHYSICAL_MAX`) takes shorter
/// substeps with its damping implicit, so its targets stay finite.
const STIFF_W_DT: f64 = 0.5;

/// What the stage's values are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StageUnit {
    /// Velocity targets, rad/s: the deadband applies, the velocity limit
    /// bounds the value.
    Velocity,
    /// Position targets, rad: the velocity limit bounds the rate.
    Position,
}

/// The stage's parameters, SI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StageParams {
    /// Natural frequency, rad/s; `None`: no response (the target is the
    /// command).
    pub frequency_rad_s: Option<f64>,
    /// Damping ratio.
    pub damping_ratio: f64,
    /// Velocity limit, rad/s (infinite: none).
    pub max_velocity_rad_s: f64,
    /// Deadband of velocity commands, rad/s.
    pub deadband_rad_s: f64,
}

impl Default for StageParams {
    fn default() -> Self {
        StageParams {
            frequency_rad_s: None,
            damping_ratio: 1.0,
            max_velocity_rad_s: f64::INFINITY,
            deadband_rad_s: 0.0,
        }
    }
}

impl StageParams {
    /// The stage `params` give (`[actuator]`).
    pub fn from_params(params: &PhysicalParams) -> StageParams {
        let a = &params.actuator;
        StageParams {
            frequency_rad_s: a.frequency_rad_s,
            damping_ratio: a.damping_ratio.unwrap_or(1.0),
            max_velocity_rad_s: a.max_velocity_deg_s.map_or(f64::INFINITY, f64::to_radians),
            deadband_rad_s: a.deadband_deg_s.unwrap_or(0.0).to_radians(),
        }
    }

    /// True when the stage passes commands through unchanged.
    pub fn is_identity(&self) -> bool {
        self.frequency_rad_s.is_none()
            && self.max_velocity_rad_s.is_infinite()
            && self.deadband_rad_s == 0.0
    }

    /// True when the target moves between commands (a response or a rate
    /// limit), so that it must be integrated at every engine step, not
    /// only when a command arrives.
    pub fn is_dynamic(&self, unit: StageUnit) -> bool {
        self.frequency_rad_s.is_some()
            || (unit == StageUnit::Position && self.max_velocity_rad_s.is_finite())
    }
}

/// The stage of one simulation: its parameters and, per joint, the
/// response's state (target and its rate).
#[derive(Debug, Clone, PartialEq)]
pub struct ActuatorStage {
    params: StageParams,
    unit: StageUnit,
    target: Vec<f64>,
    rate: Vec<f64>,
}

impl ActuatorStage {
    /// A stage at rest at `initial` (the joints' first targets).
    pub fn new(params: StageParams, unit: StageUnit, initial: &[f64]) -> ActuatorStage {
        ActuatorStage {
            params,
            unit,
            target: initial.to_vec(),
            rate: vec![0.0; initial.len()],
        }
    }

    /// The parameters.
    pub fn params(&self) -> &StageParams {
        &self.params
    }

    /// The current targets.
    pub fn targets(&self) -> &[f64] {
        &self.target
    }

    /// Advances the stage by `h_s` under the commands `input` (one per
    /// joint) and returns the targets.
    pub fn advance(&mut self, input: &[f64], h_s: f64) -> &[f64] {
        let p = self.params;
        let limit = p.max_velocity_rad_s;
        for (j, &raw) in input.iter().enumerate() {
            let u = match self.unit {
                StageUnit::Velocity if raw.abs() < p.deadband_rad_s => 0.0,
                _ => raw,
            };
            let y = &mut self.target[j];
            let v = &mut self.rate[j];
            match p.frequency_rad_s {
                Some(w) => {
                    let n = (h_s / MAX_SUBSTEP_S).ceil().max(1.0) as usize;
                    let dt = h_s / n as f64;
                    let c = 2.0 * p.damping_ratio * w;
                    if w * dt <= STIFF_W_DT && c * dt <= 2.0 * STIFF_W_DT {
                        for _ in 0..n {
                            *v += dt * (w * w * (u - *y) - c * *v);
                            if self.unit == StageUnit::Position {
                                *v = v.clamp(-limit, limit);
                            }
                            *y += dt * *v;
                        }
                    } else {
                        // A stiff stage: explicit substeps would blow up
                        // (non-finite targets the engines abort on).
                        // Shorter substeps for the spring, the damping
                        // implicit: stable at any frequency and damping.
                        let n = (h_s * w / STIFF_W_DT).ceil().max(n as f64) as usize;
                        let dt = h_s / n as f64;
                        for _ in 0..n {
                            *v = (*v + dt * w * w * (u - *y)) / (1.0 + dt * c);
                            if self.unit == StageUnit::Position {
                                *v = v.clamp(-limit, limit);
                            }
                            *y += dt * *v;
                        }
                    }
                }
                None => match self.unit {
                    StageUnit::Velocity => *y = u,
                    StageUnit::Position => {
                        let step = limit * h_s;
                        *y += (u - *y).clamp(-step, step);
                    }
                },
            }
            if self.unit == StageUnit::Velocity {
                *y = y.clamp(-limit, limit);
            }
        }
        &self.target
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stage(w: Option<f64>, zeta: f64, unit: StageUnit) -> ActuatorStage {
        ActuatorStage::new(
            StageParams {
                frequency_rad_s: w,
                damping_ratio: zeta,
                ..StageParams::default()
            },
            unit,
            &[0.0],
        )
    }

    #[test]
    fn a_second_order_response_overshoots_as_its_damping_ratio_says() {
        // w = 19 rad/s, zeta = 0.5 (the real arm, METHOD.md): the step's
        // overshoot is exp(-pi zeta / sqrt(1 - zeta^2)) = 16.3 %.
        let mut s = stage(Some(19.0), 0.5, StageUnit::Velocity);
        let mut peak: f64 = 0.0;
        for _ in 0..1000 {
            peak = peak.max(s.advance(&[1.0], 1e-3)[0]);
        }
        assert!((peak - 1.163).abs() < 3e-3, "{peak}");
        assert!(
            (s.targets()[0] - 1.0).abs() < 1e-4,
            "settles on the command"
        );
        // Critically damped: no overshoot; the same answer whatever the
        // step the caller advances by.
        let (mut a, mut b) = (
            stage(Some(30.0), 1.0, StageUnit::Velocity),
            stage(Some(30.0), 1.0, StageUnit::Velocity),
        );
        for _ in 0..100 {
            a.advance(&[1.0], 1e-3);
        }
        for _ in 0..10 {
            b.advance(&[1.0], 1e-2);
        }
        assert!(a.targets()[0] <= 1.0 && (a.targets()[0] - b.targets()[0]).abs() < 1e-9);
    }

    /// The extremes core's reading accepts (`PHYSICAL_MIN`, `PHYSICAL_MAX`)
    /// keep the targets finite and bounded.
    #[test]
    fn a_stiff_stage_stays_finite() {
        for (w, zeta) in [(1e6, 1e-6), (1e6, 1e6), (1e3, 1e6), (1e-6, 1e-6)] {
            let mut s = stage(Some(w), zeta, StageUnit::Velocity);
            for _ in 0..1000 {
                s.advance(&[1.0], 1e-3);
            }
            let y = s.targets()[0];
            assert!(y.is_finite() && y.abs() <= 2.0, "w {w}, zeta {zeta}: {y}");
        }
    }

    #[test]
    fn limits_and_deadband() {
        let mut s = ActuatorStage::new(
            StageParams {
                max_velocity_rad_s: 0.5,
                deadband_rad_s: 0.1,
                ..StageParams::default()
            },
            StageUnit::Velocity,
            &[0.0, 0.0],
        );
        assert_eq!(s.advance(&[0.05, 2.0], 1e-3), [0.0, 0.5]);
        assert_eq!(s.advance(&[-0.2, -2.0], 1e-3), [-0.2, -0.5]);
        // Positions: the rate is limited.
        let mut p = ActuatorStage::new(
            StageParams {
                max_velocity_rad_s: 1.0,
                ..StageParams::default()
            },
            StageUnit::Position,
            &[0.0],
        );
        p.advance(&[1.0], 0.25);
        assert!((p.targets()[0] - 0.25).abs() < 1e-12);
        assert!(!StageParams::default().is_dynamic(StageUnit::Position));
        assert!(StageParams::default().is_identity());
    }
}
