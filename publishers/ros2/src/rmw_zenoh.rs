//! `rmw_zenoh_cpp`'s naming, from its `docs/design.md` and `src/detail/liveliness_utils.cpp`
//! (ros2/rmw_zenoh): topic key expressions, liveliness tokens (what `ros2 node list` and
//! `ros2 topic list` read), the QoS string inside a token, the entity GID and the attachment
//! every published sample carries.
//!
//! - Topic key expression: `<domain>/<topic without its leading and trailing '/'>/<DDS type
//!   name>/<RIHS01 hash>`.
//! - Liveliness token: `@ros2_lv/<domain>/<session zid>/<node id>/<entity id>/<NN|MP|MS>/
//!   <enclave>/<namespace>/<node name>`, and for a publisher or subscription
//!   `/<topic>/<DDS type name>/<hash>/<qos>`; in names, '/' becomes '%' (so the root namespace
//!   and enclave `/` are `%`).
//! - GID (16 bytes): XXH3-128 of the entity's token, low 64 bits then high 64 bits, each little
//!   endian.
//! - Attachment (zenoh-ext serialization, `attachment_helpers.cpp`): the sequence number
//!   (i64 LE, from 1), the source timestamp (i64 LE, ns since the epoch), the GID as a
//!   length-prefixed byte array (`0x10` and 16 bytes): 33 bytes ("positional", ros2/rmw_zenoh
//!   #601: Rolling 0.6.0, Jazzy 0.2.4, Humble 0.1.2 and later). The releases before on Zenoh 1.x
//!   (Jazzy 0.2.0–0.2.3, Humble 0.1.0–0.1.1) put each value after its name as a zenoh-ext
//!   string (`"sequence_number"`, `"source_timestamp"`, `"source_gid"`): 77 bytes ("keyed").
//!   Both are read ([`Attachment::decode_any`]); the positional one is written.
//! - Distributions ([`RosDistro`]): Humble has no type hashes, so its rmw_zenoh writes
//!   `TypeHashNotSupported` where the RIHS01 hash goes, in keys and tokens.
//! - Releases ([`Conventions`]): the releases before the current ones on Zenoh 1.x wrote the
//!   keyed attachment (Humble 0.1.0–0.1.1, Jazzy 0.2.0–0.2.3) and took transient local as the
//!   default durability (Humble 0.1.0–0.1.1, Jazzy 0.2.0–0.2.2; volatile since
//!   ros2/rmw_zenoh#521, in Jazzy 0.2.3 and Humble 0.1.2), from rmw_zenoh_cpp's CHANGELOG.rst
//!   on the humble and jazzy branches.

use thiserror::Error;

use crate::types::TypeInfo;

/// The admin space of `rmw_zenoh_cpp`'s liveliness tokens.
pub const ADMIN_SPACE: &str = "@ros2_lv";

/// What rmw_zenoh on Humble writes where a type hash goes.
pub const TYPE_HASH_NOT_SUPPORTED: &str = "TypeHashNotSupported";

/// A ROS 2 distribution, as far as rmw_zenoh's wire format differs between them (its current
/// release on each: docs/ros2.md, "ROS 2 distributions").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RosDistro {
    Humble,
    #[default]
    Jazzy,
    Kilted,
    Rolling,
}

impl RosDistro {
    pub const ALL: [RosDistro; 4] = [
        RosDistro::Humble,
        RosDistro::Jazzy,
        RosDistro::Kilted,
        RosDistro::Rolling,
    ];

    pub fn name(self) -> &'static str {
        match self {
            RosDistro::Humble => "humble",
            RosDistro::Jazzy => "jazzy",
            RosDistro::Kilted => "kilted",
            RosDistro::Rolling => "rolling",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|d| d.name() == name)
    }

    /// Type `t` as this distribution names it in keys and tokens: Humble has no type hashes
    /// (REP 2011 came with Iron), its rmw_zenoh writes [`TYPE_HASH_NOT_SUPPORTED`].
    pub fn type_info(self, t: &TypeInfo) -> TypeInfo {
        match self {
            RosDistro::Humble => TypeInfo {
                hash: TYPE_HASH_NOT_SUPPORTED.into(),
                ..t.clone()
            },
            _ => t.clone(),
        }
    }
}

/// What differs on the wire between the releases of one distribution's rmw_zenoh: the
/// attachment layout and the default durability a token's QoS string is written against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Conventions {
    /// Write the keyed attachment (each value after its name), else the positional one.
    pub keyed_attachment: bool,
    /// The release's default durability is transient local (before ros2/rmw_zenoh#521).
    pub transient_local_default: bool,
}

/// Why an `--rmw-zenoh-release` was refused.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("--rmw-zenoh-release {release} with --ros-distro {distro}: {reason}")]
pub struct ReleaseError {
    pub distro: &'static str,
    pub release: String,
    pub reason: &'static str,
}

impl RosDistro {
    /// The conventions of rmw_zenoh release `release` (`X.Y.Z`) of this distribution; `None`:
    /// its current release (positional attachment, volatile default). Humble's releases are
    /// 0.1.x, Jazzy's 0.2.x; Kilted's (0.6.x) and Rolling's have the current conventions from
    /// the start.
    pub fn conventions(self, release: Option<&str>) -> Result<Conventions, ReleaseError> {
        let Some(release) = release else {
            return Ok(Conventions::default());
        };
        let err = |reason| ReleaseError {
            distro: self.name(),
            release: release.to_string(),
            reason,
        };
        let v: Vec<u32> = release
            .split('.')
            .map(|p| p.parse::<u32>())
            .collect::<Result<_, _>>()
            .map_err(|_| err("not X.Y.Z"))?;
        let [major, minor, patch] = v[..] else {
            return Err(err("not X.Y.Z"));
        };
        // (the distribution's 0.<series>.x, first positional patch, first volatile-default patch)
        let (series, positional_from, volatile_from) = match self {
            RosDistro::Humble => (1, 2, 2),
            RosDistro::Jazzy => (2, 4, 3),
            RosDistro::Kilted | RosDistro::Rolling => {
                return Err(err(
                    "every release of it has the current conventions: leave the flag out",
                ))
            }
        };
        if major != 0 || minor != series {
            return Err(err(match self {
                RosDistro::Humble => "Humble's releases are 0.1.x",
                _ => "Jazzy's releases are 0.2.x",
            }));
        }
        Ok(Conventions {
            keyed_attachment: patch < positional_from,
            transient_local_default: patch < volatile_from,
        })
    }
}

impl Conventions {
    /// The attachment layout these conventions write.
    pub fn attachment_layout(self) -> AttachmentLayout {
        if self.keyed_attachment {
            AttachmentLayout::Keyed
        } else {
            AttachmentLayout::Positional
        }
    }
}

/// A ROS name (namespace, topic) in the form a token holds: '/' → '%'.
pub fn mangle(name: &str) -> String {
    name.replace('/', "%")
}

/// Why a ROS name was refused.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("ROS name {name:?}: {reason}")]
pub struct NameError {
    pub name: String,
    pub reason: &'static str,
}

fn check_tokens(name: &str, allow_empty: bool) -> Result<(), NameError> {
    let err = |reason| {
        Err(NameError {
            name: name.to_string(),
            reason,
        })
    };
    let body = name.trim_start_matches('/');
    if body.is_empty() {
        return if allow_empty { Ok(()) } else { err("is empty") };
    }
    for tok in body.split('/') {
        if tok.is_empty() {
            return err("has an empty component ('//' or a trailing '/')");
        }
        if tok.starts_with(|c: char| c.is_ascii_digit()) {
            return err("has a component starting with a digit");
        }
        if !tok.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return err("may hold only letters, digits, '_' and '/'");
        }
    }
    Ok(())
}

/// An absolute namespace (`/` or `/a/b`; a trailing '/' is dropped).
pub fn namespace(ns: &str) -> Result<String, NameError> {
    check_tokens(ns.trim_end_matches('/'), true)?;
    let body = ns.trim_matches('/');
    Ok(format!("/{body}"))
}

/// A node name: one component.
pub fn node_name(n: &str) -> Result<String, NameError> {
    check_tokens(n, false)?;
    if n.contains('/') {
        return Err(NameError {
            name: n.into(),
            reason: "a node name has no '/'",
        });
    }
    Ok(n.to_string())
}

/// The absolute topic name of `topic` in namespace `ns` (already checked by [`namespace`]).
pub fn resolve_topic(ns: &str, topic: &str) -> Result<String, NameError> {
    check_tokens(topic, false)?;
    if topic.starts_with('/') {
        Ok(topic.to_string())
    } else if ns == "/" {
        Ok(format!("/{topic}"))
    } else {
        Ok(format!("{ns}/{topic}"))
    }
}

/// `<domain>/<topic>/<type>/<hash>`.
pub fn topic_key(domain_id: u32, topic: &str, t: &TypeInfo) -> String {
    format!(
        "{domain_id}/{}/{}/{}",
        topic.trim_matches('/'),
        t.dds_name,
        t.hash
    )
}

/// rmw QoS of an entity, as far as its token tells it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    pub reliable: bool,
    pub transient_local: bool,
    /// KEEP_LAST depth.
    pub depth: u32,
}

impl Qos {
    /// The token's QoS component (`qos_to_keyexpr` of liveliness_utils.cpp):
    /// `reliability:durability:history,depth:deadline:lifespan:liveliness`, each policy's rmw
    /// enum value (reliable 1, best effort 2; transient local 1, volatile 2) left out when it is
    /// rmw_zenoh's default (qos.cpp: reliable, **volatile**, keep last, depth 42, the rest
    /// infinite/automatic). The default durability was transient local until ros2/rmw_zenoh#521
    /// (March 2025, backported to Jazzy and Humble): receivers rebuild a token from its parts with
    /// their defaults and hash it into the GID, so a token written with the old default gets a
    /// GID other than the one in its samples' attachments.
    pub fn keyexpr(&self) -> String {
        self.keyexpr_against(false)
    }

    /// [`Qos::keyexpr`] against a release whose default durability is transient local
    /// (`transient_local_default`: before ros2/rmw_zenoh#521) or volatile.
    pub fn keyexpr_against(&self, transient_local_default: bool) -> String {
        let rel = if self.reliable { "" } else { "2" };
        let dur = match (self.transient_local, transient_local_default) {
            (true, false) => "1",
            (false, true) => "2",
            _ => "",
        };
        let depth = if self.depth == 42 {
            String::new()
        } else {
            self.depth.to_string()
        };
        format!("{rel}:{dur}:,{depth}:,:,:,,")
    }
}

/// Entity kinds of a token.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EntityKind {
    Node,
    Publisher,
    Subscription,
}

impl EntityKind {
    pub fn code(self) -> &'static str {
        match self {
            EntityKind::Node => "NN",
            EntityKind::Publisher => "MP",
            EntityKind::Subscription => "MS",
        }
    }
}

/// Who the node is on the ROS graph.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeIdentity {
    pub domain_id: u32,
    /// The Zenoh session's id, as text.
    pub zid: String,
    /// Absolute namespace.
    pub namespace: String,
    pub name: String,
    /// Its rmw_zenoh release's conventions: the QoS strings of its tokens are written against
    /// the release's default durability ([`Qos::keyexpr_against`]), its samples carry the
    /// release's attachment layout.
    pub conventions: Conventions,
}

impl NodeIdentity {
    /// The liveliness token of entity `entity_id` (0 is the node itself).
    pub fn token(
        &self,
        kind: EntityKind,
        entity_id: u32,
        topic: Option<(&str, &TypeInfo, Qos)>,
    ) -> String {
        let mut s = format!(
            "{ADMIN_SPACE}/{}/{}/0/{entity_id}/{}/%/{}/{}",
            self.domain_id,
            self.zid,
            kind.code(),
            mangle(&self.namespace),
            self.name
        );
        if let Some((topic, t, qos)) = topic {
            s.push_str(&format!(
                "/{}/{}/{}/{}",
                mangle(topic),
                t.dds_name,
                t.hash,
                qos.keyexpr_against(self.conventions.transient_local_default)
            ));
        }
        s
    }
}

/// The GID rmw_zenoh_cpp gives the entity of liveliness token `token`.
pub fn gid(token: &str) -> [u8; 16] {
    let h = xxhash_rust::xxh3::xxh3_128(token.as_bytes());
    let mut g = [0u8; 16];
    g[..8].copy_from_slice(&(h as u64).to_le_bytes());
    g[8..].copy_from_slice(&((h >> 64) as u64).to_le_bytes());
    g
}

/// The two attachment layouts (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AttachmentLayout {
    Positional,
    Keyed,
}

impl AttachmentLayout {
    pub fn name(self) -> &'static str {
        match self {
            AttachmentLayout::Positional => "positional",
            AttachmentLayout::Keyed => "keyed",
        }
    }
}

/// A sample's attachment (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Attachment {
    pub sequence_number: i64,
    pub source_timestamp_ns: i64,
    pub source_gid: [u8; 16],
}

/// Length of an encoded [`Attachment`].
pub const ATTACHMENT_LEN: usize = 33;

impl Attachment {
    /// The attachment in `layout`.
    pub fn encode_as(&self, layout: AttachmentLayout) -> Vec<u8> {
        let positional = self.encode();
        match layout {
            AttachmentLayout::Positional => positional.to_vec(),
            AttachmentLayout::Keyed => {
                let mut k = Vec::with_capacity(77);
                for (key, v) in [
                    ("sequence_number", &positional[..8]),
                    ("source_timestamp", &positional[8..16]),
                    ("source_gid", &positional[16..]),
                ] {
                    k.push(key.len() as u8);
                    k.extend_from_slice(key.as_bytes());
                    k.extend_from_slice(v);
                }
                k
            }
        }
    }

    /// The positional attachment.
    pub fn encode(&self) -> [u8; ATTACHMENT_LEN] {
        let mut b = [0u8; ATTACHMENT_LEN];
        b[..8].copy_from_slice(&self.sequence_number.to_le_bytes());
        b[8..16].copy_from_slice(&self.source_timestamp_ns.to_le_bytes());
        b[16] = 16;
        b[17..].copy_from_slice(&self.source_gid);
        b
    }

    /// Reads an attachment in either layout.
    pub fn decode_any(b: &[u8]) -> Option<(Self, AttachmentLayout)> {
        if let Some(a) = Self::decode(b) {
            return Some((a, AttachmentLayout::Positional));
        }
        // Keyed: each value after its name (a zenoh-ext string: one length byte, the bytes).
        fn field<'a>(r: &mut &'a [u8], key: &str, len: usize) -> Option<&'a [u8]> {
            let rest = r
                .strip_prefix(&[key.len() as u8][..])?
                .strip_prefix(key.as_bytes())?;
            if rest.len() < len {
                return None;
            }
            let (v, rest) = rest.split_at(len);
            *r = rest;
            Some(v)
        }
        let mut r = b;
        let seq = field(&mut r, "sequence_number", 8)?.try_into().ok()?;
        let stamp = field(&mut r, "source_timestamp", 8)?.try_into().ok()?;
        let gid = field(&mut r, "source_gid", 17)?;
        if gid[0] != 16 || !r.is_empty() {
            return None;
        }
        let a = Self {
            sequence_number: i64::from_le_bytes(seq),
            source_timestamp_ns: i64::from_le_bytes(stamp),
            source_gid: gid[1..].try_into().ok()?,
        };
        Some((a, AttachmentLayout::Keyed))
    }

    /// Reads a positional attachment; `None` if it does not have this shape.
    pub fn decode(b: &[u8]) -> Option<Self> {
        if b.len() != ATTACHMENT_LEN || b[16] != 16 {
            return None;
        }
        Some(Self {
            sequence_number: i64::from_le_bytes(b[..8].try_into().ok()?),
            source_timestamp_ns: i64::from_le_bytes(b[8..16].try_into().ok()?),
            source_gid: b[17..].try_into().ok()?,
        })
    }
}

/// Splits a topic key expression `<domain>/<topic…>/<type>/<hash>` into its topic, type and
/// hash (`None` if it has fewer than four parts).
pub fn split_topic_key(key: &str) -> Option<(&str, &str, &str)> {
    let (rest, hash) = key.rsplit_once('/')?;
    let (rest, ty) = rest.rsplit_once('/')?;
    let (_, topic) = rest.split_once('/')?;
    Some((topic, ty, hash))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::{TypeInfo, GRID_MAP};

    #[test]
    fn names_resolve_and_bad_ones_are_refused() {
        assert_eq!(namespace("/").unwrap(), "/");
        assert_eq!(namespace("robot1/").unwrap(), "/robot1");
        assert_eq!(
            resolve_topic("/", "pheromone/grid_map").unwrap(),
            "/pheromone/grid_map"
        );
        assert_eq!(resolve_topic("/r1", "amcl_pose").unwrap(), "/r1/amcl_pose");
        assert_eq!(resolve_topic("/r1", "/amcl_pose").unwrap(), "/amcl_pose");
        assert!(resolve_topic("/", "a//b").is_err());
        assert!(resolve_topic("/", "1a").is_err());
        assert!(node_name("a/b").is_err());
        assert!(namespace("/a-b").is_err());
    }

    #[test]
    fn keys_and_tokens_have_rmw_zenohs_shape() {
        let t = TypeInfo::of(GRID_MAP);
        let key = topic_key(3, "/pheromone/grid_map", &t);
        assert_eq!(
            key,
            format!(
                "3/pheromone/grid_map/grid_map_msgs::msg::dds_::GridMap_/{}",
                t.hash
            )
        );
        assert_eq!(
            split_topic_key(&key),
            Some((
                "pheromone/grid_map",
                "grid_map_msgs::msg::dds_::GridMap_",
                t.hash.as_str()
            ))
        );
        let id = NodeIdentity {
            domain_id: 3,
            zid: "abc".into(),
            namespace: "/".into(),
            name: "pheromone".into(),
            conventions: Conventions::default(),
        };
        assert_eq!(
            id.token(EntityKind::Node, 0, None),
            "@ros2_lv/3/abc/0/0/NN/%/%/pheromone"
        );
        let qos = Qos {
            reliable: true,
            transient_local: false,
            depth: 1,
        };
        let tok = id.token(
            EntityKind::Publisher,
            1,
            Some(("/pheromone/grid_map", &t, qos)),
        );
        assert_eq!(
            tok,
            format!(
                "@ros2_lv/3/abc/0/1/MP/%/%/pheromone/%pheromone%grid_map/\
                 grid_map_msgs::msg::dds_::GridMap_/{}/::,1:,:,:,,",
                t.hash
            )
        );
        let tl = Qos {
            transient_local: true,
            depth: 42,
            ..qos
        };
        assert_eq!(tl.keyexpr(), ":1:,:,:,:,,");
        // Against a release whose default durability is transient local.
        assert_eq!(tl.keyexpr_against(true), "::,:,:,:,,");
        assert_eq!(qos.keyexpr_against(true), ":2:,1:,:,:,,");
        let humble = RosDistro::Humble.type_info(&t);
        assert_eq!(
            topic_key(0, "/m", &humble),
            "0/m/grid_map_msgs::msg::dds_::GridMap_/TypeHashNotSupported"
        );
        assert_eq!(RosDistro::Rolling.type_info(&t), t);
        assert_eq!(RosDistro::from_name("kilted"), Some(RosDistro::Kilted));
        assert_eq!(RosDistro::from_name("iron"), None);
        assert_ne!(gid(&tok), gid(&id.token(EntityKind::Node, 0, None)));
    }

    #[test]
    fn attachment_round_trips_and_refuses_other_shapes() {
        let a = Attachment {
            sequence_number: 5,
            source_timestamp_ns: 1_700_000_000_000_000_000,
            source_gid: [7; 16],
        };
        let b = a.encode();
        assert_eq!(b[16], 16);
        assert_eq!(Attachment::decode(&b), Some(a));
        assert_eq!(Attachment::decode(&b[..32]), None);
        assert_eq!(
            Attachment::decode_any(&b),
            Some((a, AttachmentLayout::Positional))
        );
        // Keyed, as zenoh-ext serializes ("sequence_number", i64, "source_timestamp", i64,
        // "source_gid", 16 bytes).
        let mut k = Vec::new();
        for (key, v) in [
            ("sequence_number", &b[..8]),
            ("source_timestamp", &b[8..16]),
            ("source_gid", &b[16..]),
        ] {
            k.push(key.len() as u8);
            k.extend_from_slice(key.as_bytes());
            k.extend_from_slice(v);
        }
        assert_eq!(k.len(), 77);
        assert_eq!(a.encode_as(AttachmentLayout::Keyed), k);
        assert_eq!(a.encode_as(AttachmentLayout::Positional), b.to_vec());
        assert_eq!(
            Attachment::decode_any(&k),
            Some((a, AttachmentLayout::Keyed))
        );
        assert_eq!(Attachment::decode_any(&k[..76]), None);
        k[1] = b'S';
        assert_eq!(Attachment::decode_any(&k), None);
    }

    #[test]
    fn releases_pick_their_conventions() {
        let c = |d: RosDistro, r| d.conventions(Some(r)).unwrap();
        let keyed_tl = Conventions {
            keyed_attachment: true,
            transient_local_default: true,
        };
        assert_eq!(c(RosDistro::Humble, "0.1.1"), keyed_tl);
        assert_eq!(c(RosDistro::Humble, "0.1.2"), Conventions::default());
        assert_eq!(c(RosDistro::Jazzy, "0.2.2"), keyed_tl);
        assert_eq!(
            c(RosDistro::Jazzy, "0.2.3"),
            Conventions {
                keyed_attachment: true,
                transient_local_default: false,
            }
        );
        assert_eq!(c(RosDistro::Jazzy, "0.2.4"), Conventions::default());
        assert_eq!(
            RosDistro::Jazzy.conventions(None),
            Ok(Conventions::default())
        );
        assert!(RosDistro::Jazzy.conventions(Some("0.1.1")).is_err());
        assert!(RosDistro::Humble.conventions(Some("0.1")).is_err());
        assert!(RosDistro::Rolling.conventions(Some("0.6.0")).is_err());
    }
}
