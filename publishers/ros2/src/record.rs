//! ROS 2 MCAP files (profile `ros2`, schema encoding `ros2msg`, message encoding `cdr`): the
//! messages `pheromone ros2` publishes, written with the `mcap` crate for `ros2 bag play` and
//! Foxglove, in the form rosbag2's MCAP storage plugin writes
//! (`rosbag2_storage_mcap/src/mcap_storage.cpp`, `create_topic` and `update_metadata`): schemas
//! in the `.msg` grammar ([`crate::types::ros2msg_schema`]), each channel's metadata holding its
//! `offered_qos_profiles` (YAML, as `rosbag2_storage/src/rosbag2_storage/qos.cpp` writes them for
//! bag version 9) and its `topic_type_hash` (RIHS01), and at the end a `rosbag2` metadata record
//! whose `serialized_metadata` is the bag's metadata (YAML, version 9: topics, types, QoS, hashes,
//! message counts, start and duration). Each [`McapRecorder::end_frame`] closes the current
//! chunk and flushes the file, so a process that dies leaves a file a streaming reader reads up
//! to its last frame; [`McapRecorder::finish`] writes the metadata, summary and footer.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use thiserror::Error;

use crate::rmw_zenoh::Qos;
use crate::types::{ros2msg_schema, TypeInfo, GRID_MAP, OCCUPANCY_GRID};

/// The ROS 2 distribution whose type hashes and bag format the files follow.
pub const ROS_DISTRO: &str = "jazzy";

/// The QoS a recorded topic is declared to have been offered with: maps (GridMap,
/// OccupancyGrid) as a map server offers them, reliable and transient local, keep last 1, so
/// `ros2 bag play` republishes them latched; every other topic reliable and volatile, keep
/// last 1 (the node's publishers).
pub fn recorded_qos(t: &TypeInfo) -> Qos {
    Qos {
        reliable: true,
        transient_local: t.name == GRID_MAP || t.name == OCCUPANCY_GRID,
        depth: 1,
    }
}

/// One offered QoS profile as a YAML sequence of one map, as rosbag2 writes
/// `offered_qos_profiles` (`serialize_rclcpp_qos_vector`, bag version 9: policies by name,
/// infinite durations as `RMW_DURATION_INFINITE`); lines after the first are indented by
/// `indent`.
pub fn qos_yaml(q: Qos, indent: &str) -> String {
    let infinite = ["    sec: 9223372036", "    nsec: 854775807"];
    let reliability = if q.reliable {
        "reliable"
    } else {
        "best_effort"
    };
    let durability = if q.transient_local {
        "transient_local"
    } else {
        "volatile"
    };
    let mut lines = vec![
        "- history: keep_last".to_string(),
        format!("  depth: {}", q.depth),
        format!("  reliability: {reliability}"),
        format!("  durability: {durability}"),
    ];
    for key in ["deadline", "lifespan", "liveliness_lease_duration"] {
        if key == "liveliness_lease_duration" {
            lines.push("  liveliness: automatic".into());
        }
        lines.push(format!("  {key}:"));
        lines.extend(infinite.iter().map(|l| l.to_string()));
    }
    lines.push("  avoid_ros_namespace_conventions: false".into());
    lines.join(&format!("\n{indent}"))
}

#[derive(Debug, Error)]
#[error("MCAP file {path}: {action}: {detail}")]
pub struct RecordError {
    pub path: PathBuf,
    pub action: &'static str,
    pub detail: String,
}

/// A recorded topic.
struct Topic {
    name: String,
    channel: u16,
    type_name: &'static str,
    hash: String,
    qos: Qos,
    messages: u64,
}

/// An MCAP file being written.
pub struct McapRecorder {
    path: PathBuf,
    writer: mcap::Writer<BufWriter<File>>,
    topics: Vec<Topic>,
    sequence: u32,
    /// The smallest and largest log time written (ns).
    span: Option<(u64, u64)>,
    pub messages: u64,
    pub bytes: u64,
    /// Whether a write failed and the file was renamed to `<path>.partial`.
    partial: std::cell::Cell<bool>,
}

/// `<path>.partial`: where an incomplete recording is left.
pub fn partial_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".partial");
    PathBuf::from(name)
}

/// Renames `path` to [`partial_path`] once (`done` remembers), returning the sentence the error
/// ends with.
fn mark_partial(path: &Path, done: &std::cell::Cell<bool>) -> Option<String> {
    if done.replace(true) {
        return None;
    }
    let to = partial_path(path);
    Some(match std::fs::rename(path, &to) {
        Ok(()) => format!("; the incomplete recording was renamed to {}", to.display()),
        Err(e) => format!(
            "; the file is incomplete (renaming it to {} failed: {e})",
            to.display()
        ),
    })
}

/// How the file's chunks are compressed (`--record-compression`, `record --compression`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ChunkCompression {
    /// Uncompressed chunks.
    #[default]
    None,
    /// Zstandard (what rosbag2's MCAP storage writes with its `zstd_fast` and `zstd_small`
    /// presets).
    Zstd,
    /// LZ4 frames.
    Lz4,
}

impl ChunkCompression {
    pub const NAMES: [&'static str; 3] = ["none", "zstd", "lz4"];

    /// Whether this build compresses chunks (the crate's feature `compression`, the binary's
    /// `record-compression`): zstd and lz4 are C libraries whose build took ≈ 43 s of the
    /// default release build's CPU (docs/building.md), for a choice most runs never make.
    pub const BUILT: bool = cfg!(feature = "compression");

    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "none" => Some(Self::None),
            "zstd" => Some(Self::Zstd),
            "lz4" => Some(Self::Lz4),
            _ => None,
        }
    }

    #[cfg(feature = "compression")]
    fn mcap(self) -> Option<mcap::Compression> {
        match self {
            Self::None => None,
            Self::Zstd => Some(mcap::Compression::Zstd),
            Self::Lz4 => Some(mcap::Compression::Lz4),
        }
    }

    #[cfg(not(feature = "compression"))]
    fn mcap(self) -> Option<mcap::Compression> {
        None
    }
}

impl McapRecorder {
    /// A new file with uncompressed chunks.
    pub fn create(path: &Path) -> Result<Self, RecordError> {
        Self::create_with(path, ChunkCompression::None)
    }

    /// A new file whose chunks are compressed with `compression`.
    pub fn create_with(path: &Path, compression: ChunkCompression) -> Result<Self, RecordError> {
        let err = |action, e: &dyn std::fmt::Display| RecordError {
            path: path.to_path_buf(),
            action,
            detail: e.to_string(),
        };
        if compression != ChunkCompression::None && !ChunkCompression::BUILT {
            return Err(err(
                "compress chunks",
                &"this pheromone was built without zstd and lz4 (cargo feature \
                  `record-compression`, or `zenoh`); record uncompressed or rebuild with it",
            ));
        }
        // A regular file or a new path only (never through a link, into a FIFO or a device).
        let file = pheromone_field::outfile::open_in_place(path).map_err(|e| err("create", &e))?;
        let writer = mcap::WriteOptions::new()
            .profile("ros2")
            .library("pheromone-ros2")
            .compression(compression.mcap())
            .create(BufWriter::new(file))
            .map_err(|e| {
                let note = mark_partial(path, &std::cell::Cell::new(false)).unwrap_or_default();
                err("write header", &format!("{e}{note}"))
            })?;
        Ok(Self {
            path: path.to_path_buf(),
            writer,
            topics: Vec::new(),
            sequence: 0,
            span: None,
            messages: 0,
            bytes: 0,
            partial: std::cell::Cell::new(false),
        })
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The error of a failed write. The file is left incomplete (no summary, maybe a cut
    /// record): it is renamed to `<path>.partial` at the first error, so nothing that looks
    /// like a whole recording is left under the name asked for, and the error says so.
    fn err(&self, action: &'static str, e: impl std::fmt::Display) -> RecordError {
        let mut detail = e.to_string();
        if let Some(note) = mark_partial(&self.path, &self.partial) {
            detail.push_str(&note);
        }
        RecordError {
            path: self.path.clone(),
            action,
            detail,
        }
    }

    /// Adds a topic of type `t` (absolute ROS name), offered with [`recorded_qos`]; returns its
    /// index for [`Self::write`].
    pub fn add_topic(&mut self, topic: &str, t: &TypeInfo) -> Result<usize, RecordError> {
        let schema = self
            .writer
            .add_schema(t.name, "ros2msg", ros2msg_schema(t.name).as_bytes())
            .map_err(|e| self.err("add schema", e))?;
        let qos = recorded_qos(t);
        let metadata = BTreeMap::from([
            ("offered_qos_profiles".to_string(), qos_yaml(qos, "")),
            ("topic_type_hash".to_string(), t.hash.clone()),
        ]);
        let channel = self
            .writer
            .add_channel(schema, topic, "cdr", &metadata)
            .map_err(|e| self.err("add channel", e))?;
        self.topics.push(Topic {
            name: topic.to_string(),
            channel,
            type_name: t.name,
            hash: t.hash.clone(),
            qos,
            messages: 0,
        });
        Ok(self.topics.len() - 1)
    }

    /// Writes one CDR message on topic `index`, logged at `log_time_ns` (ns since the epoch).
    pub fn write(&mut self, index: usize, log_time_ns: u64, cdr: &[u8]) -> Result<(), RecordError> {
        self.sequence = self.sequence.wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id: self.topics[index].channel,
            sequence: self.sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        self.writer
            .write_to_known_channel(&header, cdr)
            .map_err(|e| self.err("write message", e))?;
        self.messages += 1;
        self.bytes += cdr.len() as u64;
        self.topics[index].messages += 1;
        self.span = Some(match self.span {
            Some((lo, hi)) => (lo.min(log_time_ns), hi.max(log_time_ns)),
            None => (log_time_ns, log_time_ns),
        });
        Ok(())
    }

    /// Closes the chunk and flushes: the file is readable up to here.
    pub fn end_frame(&mut self) -> Result<(), RecordError> {
        self.writer.flush().map_err(|e| self.err("flush", e))
    }

    /// The bag's metadata as rosbag2 serializes it (`YAML::convert<BagMetadata>::encode`,
    /// version 9), for the `rosbag2` metadata record.
    pub fn bag_metadata_yaml(&self) -> String {
        let file = self
            .path
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default();
        let file = serde_json::to_string(&file).expect("a string");
        let (start, duration) = self.span.map_or((0, 0), |(lo, hi)| (lo, hi - lo));
        let n = self.messages;
        let mut y: Vec<String> = [
            "version: 9",
            "storage_identifier: mcap",
            "duration:",
            &format!("  nanoseconds: {duration}"),
            "starting_time:",
            &format!("  nanoseconds_since_epoch: {start}"),
            &format!("message_count: {n}"),
            "topics_with_message_count:",
        ]
        .map(str::to_string)
        .into();
        for t in &self.topics {
            y.extend([
                "  - topic_metadata:".to_string(),
                format!(
                    "      name: {}",
                    serde_json::to_string(&t.name).expect("a string")
                ),
                format!("      type: {}", t.type_name),
                "      serialization_format: cdr".into(),
                "      offered_qos_profiles:".into(),
                format!("        {}", qos_yaml(t.qos, "        ")),
                format!("      type_description_hash: {}", t.hash),
                format!("    message_count: {}", t.messages),
            ]);
        }
        y.extend([
            "compression_format: \"\"".to_string(),
            "compression_mode: \"\"".into(),
            "relative_file_paths:".into(),
            format!("  - {file}"),
            "files:".into(),
            format!("  - path: {file}"),
            "    starting_time:".into(),
            format!("      nanoseconds_since_epoch: {start}"),
            "    duration:".into(),
            format!("      nanoseconds: {duration}"),
            format!("    message_count: {n}"),
            "custom_data: ~".into(),
            format!("ros_distro: {ROS_DISTRO}"),
        ]);
        y.join("\n") + "\n"
    }

    /// Writes the `rosbag2` metadata record, the summary and the footer.
    pub fn finish(mut self) -> Result<(), RecordError> {
        let metadata = mcap::records::Metadata {
            name: "rosbag2".into(),
            metadata: BTreeMap::from([(
                "serialized_metadata".to_string(),
                self.bag_metadata_yaml(),
            )]),
        };
        self.writer
            .write_metadata(&metadata)
            .map_err(|e| self.err("write the rosbag2 metadata", e))?;
        self.writer
            .finish()
            .map(|_| ())
            .map_err(|e| self.err("finish", e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::GRID_MAP;

    #[test]
    fn a_recorded_file_reads_back() {
        let path = std::env::temp_dir().join(format!("ros2-record-{}.mcap", std::process::id()));
        let mut r = McapRecorder::create(&path).unwrap();
        let t = TypeInfo::of(GRID_MAP);
        let i = r.add_topic("/pheromone/grid_map", &t).unwrap();
        r.write(i, 5, &[0, 1, 0, 0, 9]).unwrap();
        r.end_frame().unwrap();
        r.write(i, 6, &[0, 1, 0, 0, 8]).unwrap();
        r.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        let msgs: Vec<_> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| m.unwrap())
            .collect();
        assert_eq!(msgs.len(), 2);
        assert_eq!(msgs[0].channel.topic, "/pheromone/grid_map");
        assert_eq!(msgs[0].channel.message_encoding, "cdr");
        let schema = msgs[0].channel.schema.as_ref().unwrap();
        assert_eq!(schema.name, "grid_map_msgs/msg/GridMap");
        assert_eq!(schema.encoding, "ros2msg");
        assert_eq!(
            (msgs[0].log_time, &msgs[1].data[..]),
            (5, &[0, 1, 0, 0, 8][..])
        );
        let meta = &msgs[0].channel.metadata;
        assert_eq!(meta["topic_type_hash"], t.hash);
        assert!(meta["offered_qos_profiles"].contains("\n  durability: transient_local\n"));
        let bag: Vec<_> = mcap::read::LinearReader::new(&bytes)
            .unwrap()
            .filter_map(|r| match r.unwrap() {
                mcap::records::Record::Metadata(m) => Some(m),
                _ => None,
            })
            .collect();
        assert_eq!(bag.len(), 1);
        assert_eq!(bag[0].name, "rosbag2");
        let yaml = &bag[0].metadata["serialized_metadata"];
        assert!(yaml.contains("\nmessage_count: 2\n"), "{yaml}");
        assert!(yaml.contains("\n    message_count: 2\n"), "{yaml}");
        assert!(yaml.contains("\n  nanoseconds: 1\n"), "{yaml}");
        assert!(
            yaml.contains("\n        - history: keep_last\n          depth: 1\n"),
            "{yaml}"
        );
    }
}
