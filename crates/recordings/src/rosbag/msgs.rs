//! The ROS 2 messages a joint recording holds, decoded from CDR (the
//! serialisation of rosbag2 and DDS) with `cdr-encoding`.
//!
//! A serialised message starts with a 4-byte encapsulation header: bytes 0-1
//! name the representation (`00 01` little-endian CDR, `00 00` big-endian;
//! the XCDR2 variants `00 07`/`00 06` lay out these plain structures the
//! same way), bytes 2-3 are options. Alignment counts from after it.

use cdr_encoding::from_bytes;
use serde::de::DeserializeOwned;
use serde::Deserialize;

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds, 0 to 999 999 999.
    pub nanosec: u32,
}

impl Time {
    /// Nanoseconds since the epoch.
    pub fn ns(self) -> i64 {
        i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)
    }
}

/// `builtin_interfaces/msg/Duration`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
pub struct Duration {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds.
    pub nanosec: u32,
}

impl Duration {
    /// Nanoseconds.
    pub fn ns(self) -> i64 {
        i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct Header {
    /// When the data was taken.
    pub stamp: Time,
    /// Coordinate frame.
    pub frame_id: String,
}

/// `sensor_msgs/msg/JointState`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct JointState {
    /// Stamp and frame.
    pub header: Header,
    /// Joint names.
    pub name: Vec<String>,
    /// Positions, rad or m (empty when not measured).
    pub position: Vec<f64>,
    /// Velocities, rad/s or m/s (empty when not measured).
    pub velocity: Vec<f64>,
    /// Efforts, N m or N (empty when not measured).
    pub effort: Vec<f64>,
}

/// `std_msgs/msg/MultiArrayDimension`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct MultiArrayDimension {
    /// Label.
    pub label: String,
    /// Size.
    pub size: u32,
    /// Stride.
    pub stride: u32,
}

/// `std_msgs/msg/MultiArrayLayout`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct MultiArrayLayout {
    /// Dimensions.
    pub dim: Vec<MultiArrayDimension>,
    /// Padding elements at the front of data.
    pub data_offset: u32,
}

/// `std_msgs/msg/Float64MultiArray`: what ros2_control's forward command
/// controllers take (one value per joint, no names, no stamp).
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct Float64MultiArray {
    /// Layout (usually empty).
    pub layout: MultiArrayLayout,
    /// Values.
    pub data: Vec<f64>,
}

/// `trajectory_msgs/msg/JointTrajectoryPoint`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct JointTrajectoryPoint {
    /// Positions (may be empty).
    pub positions: Vec<f64>,
    /// Velocities (may be empty).
    pub velocities: Vec<f64>,
    /// Accelerations (may be empty).
    pub accelerations: Vec<f64>,
    /// Efforts (may be empty).
    pub effort: Vec<f64>,
    /// When the point is to be reached, from the header's stamp.
    pub time_from_start: Duration,
}

/// `trajectory_msgs/msg/JointTrajectory`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct JointTrajectory {
    /// Stamp (zero: start on receipt).
    pub header: Header,
    /// Joint names, the order of every point's values.
    pub joint_names: Vec<String>,
    /// The points.
    pub points: Vec<JointTrajectoryPoint>,
}

/// ROS 2 type name of [`JointState`].
pub const JOINT_STATE: &str = "sensor_msgs/msg/JointState";
/// ROS 2 type name of [`Float64MultiArray`].
pub const FLOAT64_MULTI_ARRAY: &str = "std_msgs/msg/Float64MultiArray";
/// ROS 2 type name of [`JointTrajectory`].
pub const JOINT_TRAJECTORY: &str = "trajectory_msgs/msg/JointTrajectory";

/// Decodes one CDR-serialised message (with its encapsulation header).
pub fn decode<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, String> {
    if bytes.len() < 4 {
        return Err(format!(
            "{} bytes, shorter than the 4-byte CDR encapsulation header",
            bytes.len()
        ));
    }
    let body = &bytes[4..];
    let decoded = match (bytes[0], bytes[1]) {
        (0, 1) | (0, 7) => from_bytes::<T, byteorder::LittleEndian>(body),
        (0, 0) | (0, 6) => from_bytes::<T, byteorder::BigEndian>(body),
        (a, b) => {
            return Err(format!(
                "unknown CDR encapsulation {a:02x} {b:02x} (expected 00 01 for little-endian CDR)"
            ))
        }
    };
    decoded
        .map(|(value, _)| value)
        .map_err(|e| format!("not a valid CDR message: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A JointState serialised by hand, byte by byte, as rclpy does.
    fn joint_state_bytes() -> Vec<u8> {
        let mut b = vec![0, 1, 0, 0];
        b.extend(7i32.to_le_bytes()); // sec
        b.extend(500u32.to_le_bytes()); // nanosec
        b.extend(5u32.to_le_bytes()); // frame_id "base" + NUL
        b.extend(b"base\0");
        b.extend([0, 0, 0]); // align to 4
        b.extend(1u32.to_le_bytes()); // one name
        b.extend(3u32.to_le_bytes());
        b.extend(b"j1\0");
        b.push(0); // align to 4
        b.extend(1u32.to_le_bytes()); // one position
                                      // align to 8 (offset from after the header)
        while (b.len() - 4) % 8 != 0 {
            b.push(0);
        }
        b.extend(0.25f64.to_le_bytes());
        b.extend(0u32.to_le_bytes()); // no velocity
        b.extend(0u32.to_le_bytes()); // no effort
        b
    }

    #[test]
    fn decodes_a_joint_state() {
        let m: JointState = decode(&joint_state_bytes()).unwrap();
        assert_eq!(m.header.stamp.ns(), 7_000_000_500);
        assert_eq!(m.header.frame_id, "base");
        assert_eq!(m.name, ["j1"]);
        assert_eq!(m.position, [0.25]);
        assert!(m.velocity.is_empty() && m.effort.is_empty());
    }

    #[test]
    fn damaged_messages_are_errors() {
        let good = joint_state_bytes();
        for cut in 0..good.len() - 8 {
            assert!(decode::<JointState>(&good[..cut]).is_err(), "cut at {cut}");
        }
        let mut bad = good.clone();
        bad[1] = 9;
        assert!(decode::<JointState>(&bad)
            .unwrap_err()
            .contains("encapsulation"));
    }
}
