//! The ROS 2 message types this crate speaks, described field by field, and what ROS 2 derives
//! from such a description: the DDS-mangled type name (`pkg::msg::dds_::Name_`, the form in
//! `rmw_zenoh_cpp`'s key expressions and liveliness tokens), the RIHS01 type hash and the
//! `ros2msg` schema text of an MCAP file.
//!
//! RIHS01 (REP 2011, `rosidl_generator_type_description`): the type's description — its own
//! fields and every type it references, sorted by name — as JSON with the default values
//! left out, `json.dumps` separators `", "` and `": "`, hashed with SHA-256 and written
//! `RIHS01_<hex>`. Field type ids are rosidl's `FieldType` constants: the primitive's id,
//! plus 48 for a fixed array, 96 for a bounded and 144 for an unbounded sequence; a nested
//! type is id 1.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;

use sha2::{Digest, Sha256};

/// A field's element type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Elem {
    Int8,
    Uint8,
    Uint16,
    Int32,
    Uint32,
    Float32,
    Float64,
    Str,
    /// A message type, `pkg/msg/Name`.
    Msg(&'static str),
}

impl Elem {
    fn type_id(self) -> u32 {
        match self {
            Elem::Msg(_) => 1,
            Elem::Int8 => 2,
            Elem::Uint8 => 3,
            Elem::Uint16 => 5,
            Elem::Int32 => 6,
            Elem::Uint32 => 7,
            Elem::Float32 => 10,
            Elem::Float64 => 11,
            Elem::Str => 17,
        }
    }

    fn msg_name(self) -> &'static str {
        match self {
            Elem::Int8 => "int8",
            Elem::Uint8 => "uint8",
            Elem::Uint16 => "uint16",
            Elem::Int32 => "int32",
            Elem::Uint32 => "uint32",
            Elem::Float32 => "float32",
            Elem::Float64 => "float64",
            Elem::Str => "string",
            Elem::Msg(n) => n,
        }
    }
}

/// `pkg/msg/Name` → `pkg/Name`: how a `.msg` file names a message type (ROS 2's interface
/// grammar has no `msg/` in a field's type) and how rosbag2 names a dependency in its `MSG:`
/// lines.
pub fn msg_reference(name: &str) -> String {
    match name.split('/').collect::<Vec<_>>()[..] {
        [pkg, "msg", base] => format!("{pkg}/{base}"),
        _ => name.to_string(),
    }
}

/// Scalar, fixed array or unbounded sequence.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    One,
    Array(u32),
    Seq,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Field {
    pub name: &'static str,
    pub elem: Elem,
    pub shape: Shape,
}

const fn f(name: &'static str, elem: Elem) -> Field {
    Field {
        name,
        elem,
        shape: Shape::One,
    }
}

const fn seq(name: &'static str, elem: Elem) -> Field {
    Field {
        name,
        elem,
        shape: Shape::Seq,
    }
}

use Elem::*;

/// A `&'static [Field]` built in a constant.
macro_rules! fields {
    ($($f:expr),* $(,)?) => {{
        const F: &[Field] = &[$($f),*];
        F
    }};
}

const TIME: &str = "builtin_interfaces/msg/Time";
const HEADER: &str = "std_msgs/msg/Header";
const POINT: &str = "geometry_msgs/msg/Point";
const QUATERNION: &str = "geometry_msgs/msg/Quaternion";
const POSE: &str = "geometry_msgs/msg/Pose";
const POSE_COV: &str = "geometry_msgs/msg/PoseWithCovariance";
pub const POSE_COV_STAMPED: &str = "geometry_msgs/msg/PoseWithCovarianceStamped";
pub const POSE_STAMPED: &str = "geometry_msgs/msg/PoseStamped";
pub const PATH: &str = "nav_msgs/msg/Path";
const MAP_META: &str = "nav_msgs/msg/MapMetaData";
pub const OCCUPANCY_GRID: &str = "nav_msgs/msg/OccupancyGrid";
const MA_DIM: &str = "std_msgs/msg/MultiArrayDimension";
const MA_LAYOUT: &str = "std_msgs/msg/MultiArrayLayout";
const F32_MULTI: &str = "std_msgs/msg/Float32MultiArray";
const GRID_MAP_INFO: &str = "grid_map_msgs/msg/GridMapInfo";
pub const GRID_MAP: &str = "grid_map_msgs/msg/GridMap";
/// The simulated time of a ROS 2 graph (`/clock`).
pub const CLOCK: &str = "rosgraph_msgs/msg/Clock";
/// This project's deposit message (docs/ros2.md, "Deposits"): no standard ROS type carries a
/// deposit's kernel and parameters.
pub const DEPOSIT: &str = "pheromone_msgs/msg/Deposit";

/// The fields of message type `name` (`pkg/msg/Name`), if this crate knows it.
pub fn fields(name: &str) -> Option<&'static [Field]> {
    Some(match name {
        TIME => fields![f("sec", Int32), f("nanosec", Uint32)],
        HEADER => fields![f("stamp", Msg(TIME)), f("frame_id", Str)],
        CLOCK => fields![f("clock", Msg(TIME))],
        POINT => fields![f("x", Float64), f("y", Float64), f("z", Float64)],
        QUATERNION => fields![
            f("x", Float64),
            f("y", Float64),
            f("z", Float64),
            f("w", Float64),
        ],
        POSE => fields![f("position", Msg(POINT)), f("orientation", Msg(QUATERNION))],
        POSE_COV => fields![
            f("pose", Msg(POSE)),
            Field {
                name: "covariance",
                elem: Float64,
                shape: Shape::Array(36),
            },
        ],
        POSE_COV_STAMPED => fields![f("header", Msg(HEADER)), f("pose", Msg(POSE_COV))],
        POSE_STAMPED => fields![f("header", Msg(HEADER)), f("pose", Msg(POSE))],
        PATH => fields![f("header", Msg(HEADER)), seq("poses", Msg(POSE_STAMPED))],
        MAP_META => fields![
            f("map_load_time", Msg(TIME)),
            f("resolution", Float32),
            f("width", Uint32),
            f("height", Uint32),
            f("origin", Msg(POSE)),
        ],
        OCCUPANCY_GRID => fields![
            f("header", Msg(HEADER)),
            f("info", Msg(MAP_META)),
            seq("data", Int8),
        ],
        MA_DIM => fields![f("label", Str), f("size", Uint32), f("stride", Uint32)],
        MA_LAYOUT => fields![seq("dim", Msg(MA_DIM)), f("data_offset", Uint32)],
        F32_MULTI => fields![f("layout", Msg(MA_LAYOUT)), seq("data", Float32)],
        GRID_MAP_INFO => fields![
            f("resolution", Float64),
            f("length_x", Float64),
            f("length_y", Float64),
            f("pose", Msg(POSE)),
        ],
        GRID_MAP => fields![
            f("header", Msg(HEADER)),
            f("info", Msg(GRID_MAP_INFO)),
            seq("layers", Str),
            seq("basic_layers", Str),
            seq("data", Msg(F32_MULTI)),
            f("outer_start_index", Uint16),
            f("inner_start_index", Uint16),
        ],
        DEPOSIT => fields![
            f("header", Msg(HEADER)),
            f("robot_id", Uint32),
            f("channel", Uint32),
            f("kernel", Str),
            f("x", Float32),
            f("y", Float32),
            f("amount", Float32),
            f("peak", Float32),
            Field {
                name: "covariance",
                elem: Float32,
                shape: Shape::Array(3),
            },
            f("range", Float32),
            f("gamma_max", Float32),
            f("sigma", Float32),
            f("plateau", Float32),
            f("slope", Float32),
        ],
        _ => return None,
    })
}

/// `pkg/msg/Name` → `pkg::msg::dds_::Name_`.
pub fn dds_name(name: &str) -> String {
    let (pkg_msg, base) = name.rsplit_once('/').unwrap_or(("", name));
    format!("{}::dds_::{base}_", pkg_msg.replace('/', "::"))
}

/// `name` and every type it references, directly or not (sorted by name, `name` included).
fn closure(name: &'static str) -> BTreeMap<&'static str, &'static [Field]> {
    let mut out = BTreeMap::new();
    let mut todo = vec![name];
    while let Some(n) = todo.pop() {
        if out.contains_key(n) {
            continue;
        }
        let fs = fields(n).unwrap_or_else(|| panic!("unknown message type {n}"));
        out.insert(n, fs);
        for fl in fs {
            if let Msg(sub) = fl.elem {
                todo.push(sub);
            }
        }
    }
    out
}

fn json_str(s: &str) -> String {
    serde_json::to_string(s).expect("a string serializes")
}

fn description_json(name: &str, fs: &[Field]) -> String {
    let mut s = format!("{{\"type_name\": {}, \"fields\": [", json_str(name));
    for (i, fl) in fs.iter().enumerate() {
        let (add, capacity) = match fl.shape {
            Shape::One => (0, 0),
            Shape::Array(n) => (48, n),
            Shape::Seq => (144, 0),
        };
        let nested = match fl.elem {
            Msg(n) => n,
            _ => "",
        };
        if i > 0 {
            s.push_str(", ");
        }
        let _ = write!(
            s,
            "{{\"name\": {}, \"type\": {{\"type_id\": {}, \"capacity\": {capacity}, \
             \"string_capacity\": 0, \"nested_type_name\": {}}}}}",
            json_str(fl.name),
            fl.elem.type_id() + add,
            json_str(nested)
        );
    }
    s.push_str("]}");
    s
}

/// The JSON ROS 2 hashes for RIHS01 (see the module documentation).
pub fn type_description_json(name: &'static str) -> String {
    let all = closure(name);
    let refs: Vec<String> = all
        .iter()
        .filter(|(n, _)| **n != name)
        .map(|(n, fs)| description_json(n, fs))
        .collect();
    format!(
        "{{\"type_description\": {}, \"referenced_type_descriptions\": [{}]}}",
        description_json(name, all[name]),
        refs.join(", ")
    )
}

/// The RIHS01 type hash of `name`: `RIHS01_` and 64 hex digits.
pub fn rihs01(name: &'static str) -> String {
    let digest = Sha256::digest(type_description_json(name).as_bytes());
    let mut s = String::with_capacity(71);
    s.push_str("RIHS01_");
    for b in digest {
        let _ = write!(s, "{b:02x}");
    }
    s
}

fn msg_text(fs: &[Field]) -> String {
    let mut s = String::new();
    for fl in fs {
        let suffix = match fl.shape {
            Shape::One => String::new(),
            Shape::Array(n) => format!("[{n}]"),
            Shape::Seq => "[]".into(),
        };
        let ty = match fl.elem {
            Msg(n) => msg_reference(n),
            e => e.msg_name().to_string(),
        };
        let _ = writeln!(s, "{ty}{suffix} {}", fl.name);
    }
    s
}

/// The `ros2msg` schema of an MCAP channel, as rosbag2 writes it
/// (`rosbag2_cpp/src/rosbag2_cpp/message_definitions/local_message_definition_source.cpp`,
/// `get_full_text` and `delimiter`): the type's `.msg` text, then depth first each type it
/// references that is not written yet, in the order of their names (a `std::set`), each after
/// an empty line, a line of 80 `=` and `MSG: pkg/Name`. Field types are `pkg/Name`, as in the
/// `.msg` grammar (`std_msgs/Header header`), never `pkg/msg/Name`.
pub fn ros2msg_schema(name: &'static str) -> String {
    fn append(name: &'static str, seen: &mut BTreeSet<&'static str>, out: &mut String) {
        let fs = fields(name).unwrap_or_else(|| panic!("unknown message type {name}"));
        out.push_str(&msg_text(fs));
        let deps: BTreeMap<String, &'static str> = fs
            .iter()
            .filter_map(|fl| match fl.elem {
                Msg(n) => Some((msg_reference(n), n)),
                _ => None,
            })
            .collect();
        for (reference, dep) in deps {
            if seen.insert(dep) {
                let _ = write!(out, "\n{}\nMSG: {reference}\n", "=".repeat(80));
                append(dep, seen, out);
            }
        }
    }
    let mut out = String::new();
    append(name, &mut BTreeSet::new(), &mut out);
    out
}

/// Everything a topic needs about its type.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TypeInfo {
    /// `pkg/msg/Name`.
    pub name: &'static str,
    /// `pkg::msg::dds_::Name_`.
    pub dds_name: String,
    /// `RIHS01_…`.
    pub hash: String,
}

impl TypeInfo {
    pub fn of(name: &'static str) -> Self {
        Self {
            name,
            dds_name: dds_name(name),
            hash: rihs01(name),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dds_names_are_mangled() {
        assert_eq!(
            dds_name(GRID_MAP),
            "grid_map_msgs::msg::dds_::GridMap_".to_string()
        );
        assert_eq!(
            dds_name(POSE_COV_STAMPED),
            "geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"
        );
    }

    /// Known answers computed by rosbags 0.11.9 (`Stores.ROS2_JAZZY`, grid_map_msgs registered
    /// from its jazzy branch's .msg files); python/tests/test_ros2.py compares every topic's
    /// hash with rosbags at test time.
    #[test]
    fn rihs01_matches_ros2_jazzy() {
        assert_eq!(
            rihs01(HEADER),
            "RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01"
        );
        assert_eq!(
            rihs01(POSE_COV_STAMPED),
            "RIHS01_26432f9803e43727d3c8f668d1fdb3c630f548af631e2f4e31382371bfea3b6e"
        );
        assert_eq!(
            rihs01(OCCUPANCY_GRID),
            "RIHS01_8d348150c12913a31ee0ec170fbf25089e4745d17035792a1ba94d6f0bc0cfc7"
        );
        assert_eq!(
            rihs01(GRID_MAP),
            "RIHS01_343b0e72887541beda6b035cc053f2d6fffaad9d6dcb2773c15a808dfca31fde"
        );
        assert_eq!(
            rihs01(PATH),
            "RIHS01_1957a5bb3cee5da65c4e52e52b65a93df227efce4c20f8458b36e73066ca334b"
        );
    }

    #[test]
    fn schema_lists_each_referenced_type_once() {
        let s = ros2msg_schema(GRID_MAP);
        assert!(s.starts_with("std_msgs/Header header\n"));
        assert!(!s.contains("/msg/"), "{s}");
        assert_eq!(s.matches("MSG: geometry_msgs/Pose\n").count(), 1);
        assert_eq!(s.matches("MSG: ").count(), 9, "{s}");
    }

    /// rosbag2's layout: depth first, dependencies by name, a blank line before each block.
    #[test]
    fn schema_is_written_as_rosbag2_writes_it() {
        let bar = "=".repeat(80);
        assert_eq!(
            ros2msg_schema(HEADER),
            format!(
                "builtin_interfaces/Time stamp\nstring frame_id\n\n{bar}\n\
                 MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
            )
        );
        let s = ros2msg_schema(POSE_COV_STAMPED);
        let blocks: Vec<&str> = s.lines().filter_map(|l| l.strip_prefix("MSG: ")).collect();
        assert_eq!(
            blocks,
            [
                "geometry_msgs/PoseWithCovariance",
                "geometry_msgs/Pose",
                "geometry_msgs/Point",
                "geometry_msgs/Quaternion",
                "std_msgs/Header",
                "builtin_interfaces/Time"
            ]
        );
        assert!(s.starts_with("std_msgs/Header header\ngeometry_msgs/PoseWithCovariance pose\n"));
    }
}
