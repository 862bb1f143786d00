//! The recorder's message threads: one per message service (robot state, telemetry), each
//! with its own node and subscriber (iceoryx2 ports stay on the thread that made them),
//! sleeping on the service's event and writing one JSON line per message as it arrives. They
//! run apart from the frames so that a burst of robot states between two frames never
//! overflows their queue while the frame loop is busy. A file is created only when its first
//! message arrives.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{Context, Result};
use handeye_wire::message::{MessageEvent, MessageSubscriber, WireMessage};
use handeye_wire::{Domain, RobotState, Telemetry, WireNode};
use serde_json::{json, Value};

use crate::cli::telemetry::telemetry_json;

/// A message type the recorder writes as a JSON line.
pub trait RecordLine: WireMessage {
    fn line(&self) -> Value;
}

impl RecordLine for RobotState {
    fn line(&self) -> Value {
        json!({
            "seq": self.seq,
            "time_ns": self.time_ns,
            "flags": self.flags,
            "last_command_seq": self.last_command_seq,
            "last_command_frame_id": self.last_command_frame_id,
            "tool_pos_m": self.tool_pos_m,
            "tool_yaw_rad": self.tool_yaw_rad,
            "joints_rad": self.joints_rad,
            "gripper_width_m": self.gripper_width_m,
            "reject": self.reject,
            "fault": self.fault,
        })
    }
}

impl RecordLine for Telemetry {
    fn line(&self) -> Value {
        telemetry_json(self)
    }
}

/// What a message thread did.
#[derive(Debug, Default)]
pub struct MessageTally {
    pub written: u64,
    /// Messages received but not written (after a write error).
    pub not_kept: u64,
    pub error: Option<String>,
}

/// A running message thread.
pub struct MessageRecorder {
    thread: JoinHandle<MessageTally>,
    /// Messages received so far (for the progress line).
    pub received: Arc<AtomicU64>,
}

impl MessageRecorder {
    /// Starts recording `T` from `domain` into `path`; it stops when `stop` is set, after
    /// writing what is queued. Returns once the subscriber exists, so nothing sent after
    /// this call is missed.
    pub fn start<T: RecordLine>(domain: &Domain, path: PathBuf, stop: Arc<AtomicBool>) -> Result<Self> {
        let received = Arc::new(AtomicU64::new(0));
        let (ready_tx, ready_rx) = std::sync::mpsc::channel::<Result<(), String>>();
        let thread = std::thread::Builder::new()
            .name(format!("record-{}", T::SERVICE))
            .spawn({
                let (domain, received) = (domain.clone(), received.clone());
                move || record::<T>(&domain, path, &stop, &received, ready_tx)
            })
            .context("starting a message thread")?;
        match ready_rx.recv() {
            Ok(Ok(())) => Ok(Self { thread, received }),
            Ok(Err(e)) => anyhow::bail!("cannot subscribe to {}: {e}", T::SERVICE),
            Err(_) => anyhow::bail!("the {} thread ended at start-up", T::SERVICE),
        }
    }

    pub fn finish(self) -> MessageTally {
        self.thread.join().unwrap_or_else(|_| MessageTally { error: Some("the message thread panicked".into()), ..MessageTally::default() })
    }
}

fn record<T: RecordLine>(
    domain: &Domain,
    path: PathBuf,
    stop: &AtomicBool,
    received: &AtomicU64,
    ready: std::sync::mpsc::Sender<Result<(), String>>,
) -> MessageTally {
    let node_name = format!("handeye-record-{}", T::SERVICE.rsplit('/').next().unwrap_or("messages"));
    let sub = WireNode::create(domain, &node_name)
        .map_err(|e| e.to_string())
        .and_then(|node| MessageSubscriber::<T>::create(&node).map(|s| (node, s)).map_err(|e| e.to_string()));
    let (_node, mut sub) = match sub {
        Ok(s) => {
            let _ = ready.send(Ok(()));
            s
        }
        Err(e) => {
            let _ = ready.send(Err(e.clone()));
            return MessageTally { error: Some(e), ..MessageTally::default() };
        }
    };
    let mut tally = MessageTally::default();
    let mut file: Option<BufWriter<File>> = None;
    let mut write = |msg: &T, tally: &mut MessageTally| {
        received.fetch_add(1, Ordering::Relaxed);
        if tally.error.is_some() {
            tally.not_kept += 1;
            return;
        }
        let result = (|| -> Result<()> {
            if file.is_none() {
                file = Some(BufWriter::new(File::create(&path).with_context(|| format!("cannot create {}", path.display()))?));
            }
            let out = file.as_mut().expect("created above");
            writeln!(out, "{}", msg.line()).with_context(|| format!("cannot write {}", path.display()))
        })();
        match result {
            Ok(()) => tally.written += 1,
            Err(e) => {
                tally.not_kept += 1;
                tally.error = Some(format!("{e:#}"));
            }
        }
    };
    while !stop.load(Ordering::Relaxed) {
        match sub.wait(Duration::from_millis(50)) {
            Ok(MessageEvent::Message(m)) => write(&m, &mut tally),
            Ok(MessageEvent::Interrupted) => break,
            Ok(_) => {}
            Err(e) => {
                tally.error.get_or_insert(e.to_string());
                break;
            }
        }
    }
    while let Some(m) = sub.try_receive() {
        write(&m, &mut tally);
    }
    if let Some(mut f) = file
        && let Err(e) = f.flush()
    {
        tally.error.get_or_insert(format!("cannot write {}: {e}", path.display()));
    }
    tally
}
