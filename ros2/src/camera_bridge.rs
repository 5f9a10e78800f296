//! `fusepose bridge ros2-camera`: a ROS 2 camera driver's colour, aligned
//! depth and CameraInfo topics → frames of one fusepose camera (iceoryx2).
//!
//! Colour and depth are paired by stamp ([`crate::pairing`]); the newest
//! CameraInfo gives the intrinsics; the colour stamp (ROS clock,
//! `CLOCK_REALTIME`) becomes the capture time on `CLOCK_MONOTONIC`
//! ([`crate::clock`]); a stamp ahead of this machine's clock (another host's
//! clock) is clamped to now. Anything unusable is dropped with a rate-limited
//! warning that says what to change; the bridge never stops on bad input.

use std::time::{Duration, Instant};

use anyhow::Context as _;
use fusepose_client::{FrameLayout, Ipc, IpcOptions, Producer, monotonic_ns};
use ros2_client::Subscription;
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};

use crate::clock::ClockMap;
use crate::image::{Pinhole, copy_planes, layout_of, pinhole};
use crate::msg::{CameraInfo, Image};
use crate::node::{open_node, topic};
use crate::pairing::{Pair, Pairer};
use crate::qos::{DurabilityArg, ReliabilityArg, profile};
use crate::ratelog::RateLog;

/// Flags of `fusepose bridge ros2-camera` (topic defaults: realsense2_camera's).
#[derive(Clone, Debug, clap::Args)]
pub struct CameraBridgeArgs {
    /// Camera name (the daemon's `cameras` entry) the frames go to.
    #[arg(long, default_value = "cam0")]
    pub name: String,
    /// ROS 2 domain id [default: $ROS_DOMAIN_ID, else 0].
    #[arg(long)]
    pub domain_id: Option<u16>,
    /// Colour image topic (rgb8 or bgr8).
    #[arg(long, default_value = "/camera/camera/color/image_raw")]
    pub color: String,
    /// Depth image topic, aligned to colour (16UC1 millimetres or 32FC1 metres).
    #[arg(long, default_value = "/camera/camera/aligned_depth_to_color/image_raw")]
    pub depth: String,
    /// CameraInfo topic of the colour camera.
    #[arg(long, default_value = "/camera/camera/color/camera_info")]
    pub info: String,
    /// Largest stamp difference of a colour and a depth image that still pair, milliseconds.
    #[arg(long, default_value_t = 10.0)]
    pub slop_ms: f64,
    /// Reliability of the image and CameraInfo readers (best-effort matches every writer).
    #[arg(long, value_enum, default_value = "best-effort")]
    pub reliability: ReliabilityArg,
    /// History depth (keep last N) of the readers.
    #[arg(long, default_value_t = 5)]
    pub history_depth: usize,
    /// Durability of the readers.
    #[arg(long, value_enum, default_value = "volatile")]
    pub durability: DurabilityArg,
    /// Warn when no frame was sent for this many seconds.
    #[arg(long, default_value_t = 5.0)]
    pub stall_s: f64,
}

const COLOR: Token = Token(0);
const DEPTH: Token = Token(1);
const INFO: Token = Token(2);

/// The three readers and when each last delivered.
struct Inputs {
    color: Subscription<Image>,
    depth: Subscription<Image>,
    info: Subscription<CameraInfo>,
    last: [Option<Instant>; 3],
}

/// The frame publisher for the current image format (created on the first pair, re-created if it changes).
struct Output {
    ipc: Ipc,
    camera: String,
    producer: Option<Producer>,
}

impl Output {
    fn producer(&mut self, layout: FrameLayout) -> anyhow::Result<&mut Producer> {
        if self.producer.as_ref().is_some_and(|p| *p.layout() != layout) {
            tracing::info!(camera = %self.camera, ?layout, "image format changed: re-creating the frame publisher");
            let next = self.producer.take().map(|p| p.next_sequence()).unwrap_or(0);
            let mut p = Producer::create(&self.ipc, &self.camera, layout)?;
            p.set_next_sequence(next);
            self.producer = Some(p);
        }
        if self.producer.is_none() {
            tracing::info!(camera = %self.camera, ?layout, "first frame pair: publishing frames");
            self.producer = Some(
                Producer::create(&self.ipc, &self.camera, layout)
                    .with_context(|| format!("creating the frame publisher of camera '{}'", self.camera))?,
            );
        }
        Ok(self.producer.as_mut().expect("set above"))
    }
}

/// Runs the camera bridge until killed.
pub fn run(args: &CameraBridgeArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.slop_ms.is_finite() && args.slop_ms >= 0.0,
        "--slop-ms must be a non-negative number of milliseconds"
    );
    let ipc = Ipc::new(&IpcOptions::from_env().with_node_name(&format!("ros2_camera_bridge_{}", args.name)))?;
    fusepose_client::validate_camera_name(&args.name).map_err(|e| anyhow::anyhow!("--name: {e}"))?;
    let mut node = open_node(crate::node::domain_id(args.domain_id)?, &format!("{}_camera_bridge", args.name))?;
    let qos = profile(args.reliability, args.history_depth, args.durability);
    let color_topic = topic(&mut node, &args.color, "sensor_msgs", "Image", &qos)?;
    let depth_topic = topic(&mut node, &args.depth, "sensor_msgs", "Image", &qos)?;
    let info_topic = topic(&mut node, &args.info, "sensor_msgs", "CameraInfo", &qos)?;
    let sub = |node: &mut ros2_client::Node, t: &ros2_client::dds::rustdds::Topic, name: &str| {
        node.create_subscription::<Image>(t, None).map_err(|e| anyhow::anyhow!("subscribing to {name}: {e:?}"))
    };
    let mut inputs = Inputs {
        color: sub(&mut node, &color_topic, &args.color)?,
        depth: sub(&mut node, &depth_topic, &args.depth)?,
        info: node
            .create_subscription::<CameraInfo>(&info_topic, None)
            .map_err(|e| anyhow::anyhow!("subscribing to {}: {e:?}", args.info))?,
        last: [None; 3],
    };
    let mut poll = Poll::new().context("creating the event poll")?;
    poll.registry().register(&mut inputs.color, COLOR, Interest::READABLE)?;
    poll.registry().register(&mut inputs.depth, DEPTH, Interest::READABLE)?;
    poll.registry().register(&mut inputs.info, INFO, Interest::READABLE)?;
    tracing::info!(
        camera = %args.name,
        domain = crate::node::domain_id(args.domain_id)?,
        color = %args.color,
        depth = %args.depth,
        info = %args.info,
        slop_ms = args.slop_ms,
        "ROS 2 camera bridge running"
    );

    let mut out = Output { ipc, camera: args.name.clone(), producer: None };
    let mut pairer: Pairer<Image> = Pairer::new((args.slop_ms * 1e6) as i64);
    let mut intrinsics: Option<Pinhole> = None;
    let mut clock = ClockMap::new();
    let mut log = RateLog::default();
    let mut events = Events::with_capacity(8);
    let mut last_sent = Instant::now();
    let stall = Duration::from_secs_f64(args.stall_s.max(0.1));
    loop {
        // Edge-triggered readiness: a short timeout also covers anything that slipped past an edge.
        if let Err(e) = poll.poll(&mut events, Some(Duration::from_millis(50)))
            && e.kind() != std::io::ErrorKind::Interrupted
        {
            return Err(e).context("waiting for DDS data");
        }
        let now = Instant::now();
        loop {
            match inputs.info.take() {
                Ok(Some((info, _))) => {
                    inputs.last[2] = Some(now);
                    match pinhole(&info) {
                        Ok(k) => intrinsics = Some(k),
                        Err(r) => {
                            intrinsics = None;
                            log.warn(r.key, || format!("{}: {}", args.info, r.message));
                        }
                    }
                }
                Ok(None) => break,
                Err(e) => {
                    log.warn("info_read", || format!("{}: undecodable CameraInfo dropped ({e:?})", args.info));
                    break;
                }
            }
        }
        let mut pairs = Vec::new();
        for (index, reader, name) in [(0usize, &inputs.color, &args.color), (1, &inputs.depth, &args.depth)] {
            loop {
                match reader.take() {
                    Ok(Some((img, _))) => {
                        inputs.last[index] = Some(now);
                        let stamp = img.header.stamp.to_ns();
                        let pair =
                            if index == 0 { pairer.push_color(stamp, img) } else { pairer.push_depth(stamp, img) };
                        pairs.extend(pair);
                    }
                    Ok(None) => break,
                    Err(e) => {
                        log.warn("image_read", || format!("{name}: undecodable Image dropped ({e:?})"));
                        break;
                    }
                }
            }
        }
        let dropped = pairer.take_dropped();
        if dropped > 0 {
            log.warn("unpaired", || {
                format!(
                    "{dropped} image(s) dropped without a partner within --slop-ms {} (colour {} / depth {}): \
                     are both streams running at the same rate and stamped by the same clock?",
                    args.slop_ms, args.color, args.depth
                )
            });
        }
        // Only the newest pair is worth a pose; older ones in the same batch are late already.
        if pairs.len() > 1 {
            let n = pairs.len() - 1;
            log.warn("backlog", || format!("{n} older frame pair(s) skipped: the bridge fell behind"));
        }
        if let Some(pair) = pairs.pop()
            && send(&mut out, &pair, intrinsics.as_ref(), &mut clock, &mut log, args)?
        {
            last_sent = now;
        }
        if now.duration_since(last_sent) >= stall {
            let age = |i: usize| match inputs.last[i] {
                Some(t) => format!("{:.1} s ago", now.duration_since(t).as_secs_f64()),
                None => "never".to_owned(),
            };
            log.warn("stalled", || {
                format!(
                    "no frame sent for {:.0} s; last message on {}: {}, {}: {}, {}: {}",
                    now.duration_since(last_sent).as_secs_f64(),
                    args.color,
                    age(0),
                    args.depth,
                    age(1),
                    args.info,
                    age(2)
                )
            });
        }
    }
}

/// Sends one pair as a frame; false (logged) when it had to be dropped.
fn send(
    out: &mut Output,
    pair: &Pair<Image>,
    k: Option<&Pinhole>,
    clock: &mut ClockMap,
    log: &mut RateLog,
    args: &CameraBridgeArgs,
) -> anyhow::Result<bool> {
    let Some(k) = k else {
        log.warn("no_info", || format!("no usable CameraInfo on {} yet: frames dropped until one arrives", args.info));
        return Ok(false);
    };
    let layout = match layout_of(&pair.color, &pair.depth, k) {
        Ok(l) => l,
        Err(r) => {
            log.warn(r.key, || r.message.clone());
            return Ok(false);
        }
    };
    let stamp = pair.color.header.stamp.to_ns();
    let Some(mut capture) = clock.ros_to_monotonic(stamp) else {
        log.warn("stamp", || {
            format!("colour stamp {stamp} ns lies before this machine booted: is the driver on sim time? dropped")
        });
        return Ok(false);
    };
    let now = monotonic_ns();
    if capture > now {
        let ahead = capture - now;
        log.warn("future", || {
            format!(
                "stamps run {:.1} ms ahead of this machine's clock (sync the clocks, e.g. chrony): clamped to now",
                ahead as f64 / 1e6
            )
        });
        capture = now;
    }
    let producer = out.producer(layout)?;
    let mut frame = match producer.loan() {
        Ok(f) => f,
        Err(e) => {
            log.warn("loan", || format!("no frame buffer free ({e}): frame dropped"));
            return Ok(false);
        }
    };
    frame.set_capture_time_ns(capture).set_intrinsics(k.fx, k.fy, k.cx, k.cy);
    let planes = frame.planes_mut();
    copy_planes(&pair.color, &pair.depth, planes.color, planes.depth);
    match frame.send() {
        Ok(sequence) => {
            tracing::debug!(sequence, stamp, capture, "frame sent");
            Ok(true)
        }
        Err(e) => {
            log.warn("send", || format!("sending the frame failed: {e}"));
            Ok(false)
        }
    }
}
