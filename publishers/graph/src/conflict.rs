//! Conflict resolution (paper 001 Sec. 5.1): robots contending for a region exchange the JSON
//! message of Listing 1 and every robot computes the same winner from the same messages.
//!
//! Order (the paper's): the higher task priority wins; then more battery; then the lower
//! capture count (it has served fewer areas); then the better sensor spec (longer LRF range,
//! then higher camera resolution); then the smaller robot id. Two conventions the paper leaves
//! open are fixed here: a larger `task-priority` number is the higher priority, and "sufficient
//! power" is read as "more battery left".

use std::cmp::Ordering;

use serde::{Deserialize, Serialize};

/// Camera resolutions, worst to best.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum RgbRes {
    None,
    Qvga,
    Vga,
    Hd,
    FullHd,
}

impl RgbRes {
    pub const ALL: [RgbRes; 5] = [
        RgbRes::None,
        RgbRes::Qvga,
        RgbRes::Vga,
        RgbRes::Hd,
        RgbRes::FullHd,
    ];

    pub fn name(self) -> &'static str {
        match self {
            RgbRes::None => "none",
            RgbRes::Qvga => "qvga",
            RgbRes::Vga => "vga",
            RgbRes::Hd => "hd",
            RgbRes::FullHd => "fullhd",
        }
    }
}

impl std::str::FromStr for RgbRes {
    type Err = ConflictError;
    fn from_str(s: &str) -> Result<Self, ConflictError> {
        RgbRes::ALL
            .into_iter()
            .find(|r| r.name() == s)
            .ok_or_else(|| ConflictError::Field {
                field: "rgb-res",
                value: s.to_string(),
                expected: "none, qvga, vga, hd or fullhd",
            })
    }
}

/// A contention message that could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ConflictError {
    #[error("contention message: {0}")]
    Json(#[source] serde_json::Error),
    #[error("contention message: not UTF-8: {0}")]
    Utf8(#[source] std::str::Utf8Error),
    #[error("contention message: field '{field}' = '{value}': expected {expected}")]
    Field {
        field: &'static str,
        value: String,
        expected: &'static str,
    },
    #[error("contention message: {len} bytes do not fit the {max}-byte buffer")]
    TooLong { len: usize, max: usize },
}

/// Listing 1, typed. `region` says which region is contended (the paper sends the message in
/// that context; here it travels with it as `"region-id"`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContendMsg {
    pub robot_id: u32,
    /// Unix time stamp (s).
    pub time_stamp_s: u64,
    pub battery_pct: u8,
    /// Areas served so far.
    pub capture_count: u32,
    pub task_id: u32,
    pub task_priority: u32,
    pub lrf_range_m: f32,
    pub rgb_res: RgbRes,
    pub region: u32,
}

impl ContendMsg {
    /// The paper's order as a total order: `Less` means `self` wins over `other`. Every robot
    /// sorting the same messages gets the same winner.
    pub fn precedence(&self, other: &Self) -> Ordering {
        other
            .task_priority
            .cmp(&self.task_priority)
            .then(other.battery_pct.cmp(&self.battery_pct))
            .then(self.capture_count.cmp(&other.capture_count))
            .then(other.lrf_range_m.total_cmp(&self.lrf_range_m))
            .then(other.rgb_res.cmp(&self.rgb_res))
            .then(self.robot_id.cmp(&other.robot_id))
            // Not part of the paper's order; only makes the order total for equal ids.
            .then(self.time_stamp_s.cmp(&other.time_stamp_s))
            .then(self.task_id.cmp(&other.task_id))
            .then(self.region.cmp(&other.region))
    }

    /// The robots that get the region: the first `room` of the contenders in the paper's order,
    /// one message per robot (the first seen counts).
    pub fn winners(contenders: &[ContendMsg], room: usize) -> Vec<u32> {
        let mut msgs: Vec<ContendMsg> = Vec::new();
        for m in contenders {
            if !msgs.iter().any(|x| x.robot_id == m.robot_id) {
                msgs.push(*m);
            }
        }
        msgs.sort_by(ContendMsg::precedence);
        msgs.into_iter().take(room).map(|m| m.robot_id).collect()
    }

    /// The JSON text of Listing 1 (string values, task and sensor spec as arrays of one-key
    /// objects) plus `"region-id"`.
    pub fn to_json(&self) -> String {
        let w = Wire {
            robot_param: WireParam {
                robot_id: format!("{:02}", self.robot_id),
                time_stamp: self.time_stamp_s.to_string(),
                battery: self.battery_pct.to_string(),
                capture_count: self.capture_count.to_string(),
                task: (
                    TaskId {
                        task_id: self.task_id.to_string(),
                    },
                    TaskPriority {
                        task_priority: self.task_priority.to_string(),
                    },
                ),
                sensor_spec: (
                    LrfRange {
                        lrf_range: format!("{}m", self.lrf_range_m),
                    },
                    Rgb {
                        rgb_res: self.rgb_res.name().to_string(),
                    },
                ),
            },
            region_id: self.region.to_string(),
        };
        serde_json::to_string(&w).expect("plain strings always serialize")
    }

    /// Reads Listing 1's JSON; every field must be present and well-formed.
    pub fn from_json(text: &str) -> Result<Self, ConflictError> {
        let w: Wire = serde_json::from_str(text).map_err(ConflictError::Json)?;
        let p = &w.robot_param;
        fn num<T: std::str::FromStr>(field: &'static str, v: &str) -> Result<T, ConflictError> {
            v.parse().map_err(|_| ConflictError::Field {
                field,
                value: v.to_string(),
                expected: "a non-negative integer in range",
            })
        }
        let battery_pct: u8 = num("battery", &p.battery)?;
        if battery_pct > 100 {
            return Err(ConflictError::Field {
                field: "battery",
                value: p.battery.clone(),
                expected: "a percentage 0..=100",
            });
        }
        let lrf = &p.sensor_spec.0.lrf_range;
        let lrf_range_m = lrf
            .strip_suffix('m')
            .and_then(|v| v.parse::<f32>().ok())
            .filter(|v| v.is_finite() && *v >= 0.0)
            .ok_or_else(|| ConflictError::Field {
                field: "LRF-range",
                value: lrf.clone(),
                expected: "a range in metres such as '4m'",
            })?;
        Ok(Self {
            robot_id: num("robot-id", &p.robot_id)?,
            time_stamp_s: num("time-stamp", &p.time_stamp)?,
            battery_pct,
            capture_count: num("capture-count", &p.capture_count)?,
            task_id: num("task-id", &p.task.0.task_id)?,
            task_priority: num("task-priority", &p.task.1.task_priority)?,
            lrf_range_m,
            rgb_res: p.sensor_spec.1.rgb_res.parse()?,
            region: num("region-id", &w.region_id)?,
        })
    }
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Wire {
    #[serde(rename = "robot-param")]
    robot_param: WireParam,
    #[serde(rename = "region-id")]
    region_id: String,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct WireParam {
    #[serde(rename = "robot-id")]
    robot_id: String,
    #[serde(rename = "time-stamp")]
    time_stamp: String,
    battery: String,
    #[serde(rename = "capture-count")]
    capture_count: String,
    task: (TaskId, TaskPriority),
    #[serde(rename = "sensor-spec")]
    sensor_spec: (LrfRange, Rgb),
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct TaskId {
    #[serde(rename = "task-id")]
    task_id: String,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct TaskPriority {
    #[serde(rename = "task-priority")]
    task_priority: String,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct LrfRange {
    #[serde(rename = "LRF-range")]
    lrf_range: String,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Rgb {
    #[serde(rename = "rgb-res")]
    rgb_res: String,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn listing_1_parses() {
        let text = r#"{"robot-param": {"robot-id": "01", "time-stamp": "1440233786",
            "battery": "79", "capture-count": "2",
            "task": [{"task-id": "8"}, {"task-priority": "1"}],
            "sensor-spec": [{"LRF-range": "4m"}, {"rgb-res": "vga"}]}, "region-id": "3"}"#;
        let m = ContendMsg::from_json(text).unwrap();
        assert_eq!(
            m,
            ContendMsg {
                robot_id: 1,
                time_stamp_s: 1440233786,
                battery_pct: 79,
                capture_count: 2,
                task_id: 8,
                task_priority: 1,
                lrf_range_m: 4.0,
                rgb_res: RgbRes::Vga,
                region: 3,
            }
        );
        assert_eq!(ContendMsg::from_json(&m.to_json()).unwrap(), m);
        let bad = text.replace("\"79\"", "\"179\"");
        let e = ContendMsg::from_json(&bad).unwrap_err().to_string();
        assert!(e.contains("battery") && e.contains("179"), "{e}");
        let bad = text.replace("4m", "four");
        assert!(ContendMsg::from_json(&bad)
            .unwrap_err()
            .to_string()
            .contains("LRF-range"));
    }
}
