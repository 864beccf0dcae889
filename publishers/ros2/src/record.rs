//! ROS 2 MCAP files (profile `ros2`, schema encoding `ros2msg`, message encoding `cdr`): the
//! messages `pheromone ros2` publishes, written with the `mcap` crate for `ros2 bag play` and
//! Foxglove. Each [`McapRecorder::end_frame`] closes the current chunk and flushes the file, so
//! a process that dies leaves a file a streaming reader reads up to its last frame;
//! [`McapRecorder::finish`] writes the summary and footer.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use thiserror::Error;

use crate::types::{ros2msg_schema, TypeInfo};

#[derive(Debug, Error)]
#[error("MCAP file {path}: {action}: {detail}")]
pub struct RecordError {
    pub path: PathBuf,
    pub action: &'static str,
    pub detail: String,
}

/// An MCAP file being written.
pub struct McapRecorder {
    path: PathBuf,
    writer: mcap::Writer<BufWriter<File>>,
    channels: Vec<(String, u16)>,
    sequence: u32,
    pub messages: u64,
    pub bytes: u64,
}

impl McapRecorder {
    pub fn create(path: &Path) -> Result<Self, RecordError> {
        let err = |action, e: &dyn std::fmt::Display| RecordError {
            path: path.to_path_buf(),
            action,
            detail: e.to_string(),
        };
        let file = File::create(path).map_err(|e| err("create", &e))?;
        let writer = mcap::WriteOptions::new()
            .profile("ros2")
            .library("pheromone-ros2")
            .compression(None)
            .create(BufWriter::new(file))
            .map_err(|e| err("write header", &e))?;
        Ok(Self {
            path: path.to_path_buf(),
            writer,
            channels: Vec::new(),
            sequence: 0,
            messages: 0,
            bytes: 0,
        })
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn err(&self, action: &'static str, e: impl std::fmt::Display) -> RecordError {
        RecordError {
            path: self.path.clone(),
            action,
            detail: e.to_string(),
        }
    }

    /// Adds a topic of type `t` (absolute ROS name); returns its index for [`Self::write`].
    pub fn add_topic(&mut self, topic: &str, t: &TypeInfo) -> Result<usize, RecordError> {
        let schema = self
            .writer
            .add_schema(t.name, "ros2msg", ros2msg_schema(t.name).as_bytes())
            .map_err(|e| self.err("add schema", e))?;
        let channel = self
            .writer
            .add_channel(schema, topic, "cdr", &BTreeMap::new())
            .map_err(|e| self.err("add channel", e))?;
        self.channels.push((topic.to_string(), channel));
        Ok(self.channels.len() - 1)
    }

    /// Writes one CDR message on topic `index`, logged at `log_time_ns` (ns since the epoch).
    pub fn write(&mut self, index: usize, log_time_ns: u64, cdr: &[u8]) -> Result<(), RecordError> {
        self.sequence = self.sequence.wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id: self.channels[index].1,
            sequence: self.sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        self.writer
            .write_to_known_channel(&header, cdr)
            .map_err(|e| self.err("write message", e))?;
        self.messages += 1;
        self.bytes += cdr.len() as u64;
        Ok(())
    }

    /// Closes the chunk and flushes: the file is readable up to here.
    pub fn end_frame(&mut self) -> Result<(), RecordError> {
        self.writer.flush().map_err(|e| self.err("flush", e))
    }

    /// Writes the summary and footer.
    pub fn finish(mut self) -> Result<(), RecordError> {
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
    }
}
