//! The antenna robot of `pheromone follower --gateway`: it reads (and deposits) through a
//! thin-client gateway, with a backup, and runs as [`super::follower_antenna`]'s robot does.

use std::time::Duration;

use iceoryx2::node::Node;
use pheromone_field::shm::Svc;
use pheromone_gateway::client::{
    ClientConfig, ClientError, DepositRetry, GatewayClient, Transport,
};

use super::follower_antenna::{
    run_antenna_robot, AntennaRobotSummary, AntennaRunOptions, ClientAir, RemoteDeposits,
};
use crate::follower::antenna_source::{AntennaRobot, GatewaySource};
use crate::follower::{AntennaFollower, FollowerConfig, FollowerConfigError};
use crate::radio::{RadioConfig, RadioConfigError};
use crate::{ProcessError, RoleOptions};

/// How a remote antenna robot reaches its gateway.
#[derive(Debug, Clone)]
pub struct RemoteFollowerOptions {
    /// The gateway, `HOST:PORT`.
    pub gateway: String,
    /// The gateway it switches to when the first does not answer.
    pub backup: Option<String>,
    /// The client ID in every frame (1–255).
    pub client_id: u8,
    /// How long each request waits for its reply, and how often it is retried.
    pub timeout: Duration,
    pub retries: u32,
    pub deposits: Option<RemoteDeposits>,
    /// Lockstep: how long a step may wait for the frame of its step.
    pub frame_timeout: Duration,
    /// The world's step (s).
    pub dt_s: f64,
    /// The simulated shared air (`[radio]`) and its seed (the scenario's): the robot is client
    /// `o.robot` on it.
    pub radio: Option<(RadioConfig, u64)>,
}

/// Why a remote antenna robot failed.
#[derive(Debug, thiserror::Error)]
pub enum RemoteFollowerError {
    /// A gateway address that does not resolve or a socket that cannot be opened.
    #[error(transparent)]
    Client(#[from] ClientError),
    #[error(transparent)]
    Config(#[from] FollowerConfigError),
    #[error(transparent)]
    Process(#[from] ProcessError),
    #[error(transparent)]
    Radio(#[from] RadioConfigError),
}

impl RemoteFollowerError {
    /// The error is the user's input (an address, the antenna's configuration).
    pub fn is_bad_input(&self) -> bool {
        !matches!(self, RemoteFollowerError::Process(_))
    }
}

/// Runs robot `o.robot`'s antenna follower (configured by `config`) through the gateway of `r`.
pub fn run_remote_follower(
    node: &Node<Svc>,
    o: &RoleOptions,
    config: &FollowerConfig,
    r: &RemoteFollowerOptions,
) -> Result<AntennaRobotSummary, RemoteFollowerError> {
    let mut client = GatewayClient::new(
        Transport::udp(&r.gateway)?,
        ClientConfig {
            client_id: r.client_id,
            timeout: r.timeout,
            retries: r.retries,
            // A restarted robot does not reuse its last run's seqs (the gateway remembers 16).
            first_seq: (std::process::id() % 256) as u8,
            deposit_retry: DepositRetry::SameGateway,
            ..ClientConfig::default()
        },
    );
    if let Some(b) = &r.backup {
        client = client.with_backup(Transport::udp(b)?);
    }
    let strategy = AntennaFollower::new(config.channel as usize, config.antenna.clone())?;
    let robot = AntennaRobot::new(o.robot, strategy, GatewaySource::new(client));
    let air = r
        .radio
        .as_ref()
        .map(|(radio, seed)| ClientAir::new(radio, o.robot, r.dt_s, *seed))
        .transpose()?;
    let run = AntennaRunOptions {
        steer_by: config.steer_by,
        dt_s: r.dt_s,
        frame_timeout: r.frame_timeout,
        deposits: r.deposits,
        air,
    };
    Ok(run_antenna_robot(node, o, robot, run)?)
}
