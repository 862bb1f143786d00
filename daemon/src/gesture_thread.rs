//! The pointing gesture tracker ([`PointingTracker`]) on a thread of its own, fed a copy of
//! every frame: its update (differencing both 640x480 views, ~1.1 ms) does not fit the hard
//! loop's 1 ms cycle, and the gripper trackers must keep running at frame rate beside it.
//!
//! Lockstep, like the worker jobs (`phase/job.rs`): the result for frame `k` is taken on
//! frame `k + `[`GESTURE_DELAY_FRAMES`], never earlier; when it is due and not there, a
//! lockstep daemon (`timing.worker_wait_ms` > 0) waits for it on that frame, so that the
//! frame on which the gesture is answered does not depend on the machine's speed. Without
//! the wait (real cameras) a late result is taken on a later frame, and a frame that finds
//! every buffer in use is not handed over (the tracker then sees every other frame).
//!
//! The frame buffers travel to the thread and back with the result: after start-up nothing
//! is allocated per frame.

use std::collections::VecDeque;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam::channel::{bounded, Receiver, Sender};
use handeye_vision::image::{ImageBuf, ImageView};
use handeye_vision::pointing::{GestureState, PointingTracker};

/// Frames between handing a frame over and taking its gesture result: two frames (67 ms at
/// 30 Hz) is twenty times the update's time.
pub const GESTURE_DELAY_FRAMES: u64 = 2;

/// Buffer pairs: those in flight, and one being filled.
const BUFFERS: usize = GESTURE_DELAY_FRAMES as usize + 2;

/// One stereo frame's copy.
struct Pair([ImageBuf; 2]);

enum Msg {
    /// The scene without the hand.
    Background(Pair),
    Frame { frame_index: u64, frame_id: u64, pair: Pair },
}

/// What the tracker made of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GestureResult {
    pub frame_index: u64,
    pub frame_id: u64,
    pub state: GestureState,
    /// The update's own time on the gesture thread, ns.
    pub update_ns: u64,
}

/// The gesture tracker's thread and the frames in flight to it.
pub struct GestureThread {
    to: Option<Sender<Msg>>,
    from: Receiver<(Option<GestureResult>, Pair)>,
    spare: Vec<Pair>,
    /// Frame indices handed over whose results are not taken yet, oldest first.
    pending: VecDeque<u64>,
    /// Results that came back before they were due, oldest first.
    early: VecDeque<GestureResult>,
    due_wait: Duration,
    handle: Option<JoinHandle<()>>,
}

impl GestureThread {
    /// Starts the thread with `tracker`, for frames of `width` x `height`; `due_wait`: how
    /// long a due result is waited for (zero: never).
    pub fn spawn(mut tracker: PointingTracker, width: usize, height: usize, due_wait: Duration) -> std::io::Result<Self> {
        let (to, jobs) = bounded::<Msg>(BUFFERS);
        let (done, from) = bounded::<(Option<GestureResult>, Pair)>(BUFFERS);
        let handle = std::thread::Builder::new().name("handeye-gesture".into()).spawn(move || {
            for msg in jobs.iter() {
                let reply = match msg {
                    Msg::Background(pair) => {
                        tracker.set_background(&pair.0[0].view(), &pair.0[1].view());
                        (None, pair)
                    }
                    Msg::Frame { frame_index, frame_id, pair } => {
                        let t0 = Instant::now();
                        let state = tracker.update(&pair.0[0].view(), &pair.0[1].view());
                        let update_ns = t0.elapsed().as_nanos() as u64;
                        (Some(GestureResult { frame_index, frame_id, state, update_ns }), pair)
                    }
                };
                if done.send(reply).is_err() {
                    break; // the owner is gone
                }
            }
        })?;
        let spare = (0..BUFFERS).map(|_| Pair([ImageBuf::new(width, height), ImageBuf::new(width, height)])).collect();
        Ok(Self { to: Some(to), from, spare, pending: VecDeque::new(), early: VecDeque::new(), due_wait, handle: Some(handle) })
    }

    /// A spare buffer pair filled with the frame; `None` when all are in flight.
    fn fill(&mut self, left: &ImageView<'_>, right: &ImageView<'_>) -> Option<Pair> {
        self.drain();
        let mut pair = self.spare.pop()?;
        for (dst, src) in pair.0.iter_mut().zip([left, right]) {
            if dst.width != src.width() || dst.height != src.height() {
                *dst = src.to_owned(); // a camera of another size: allocates once
                continue;
            }
            for y in 0..src.height() {
                dst.data[y * dst.width..(y + 1) * dst.width].copy_from_slice(src.row(y));
            }
        }
        Some(pair)
    }

    /// Makes this frame the scene without the hand; `false` when it could not be handed over.
    pub fn set_background(&mut self, left: &ImageView<'_>, right: &ImageView<'_>) -> bool {
        let Some(pair) = self.fill(left, right) else { return false };
        self.send(Msg::Background(pair))
    }

    /// Hands frame `frame_index` (id `frame_id`) over; `false` when every buffer is in flight
    /// (a late thread without lockstep) or the thread is gone.
    pub fn submit(&mut self, frame_index: u64, frame_id: u64, left: &ImageView<'_>, right: &ImageView<'_>) -> bool {
        let Some(pair) = self.fill(left, right) else { return false };
        if self.send(Msg::Frame { frame_index, frame_id, pair }) {
            self.pending.push_back(frame_index);
            true
        } else {
            false
        }
    }

    fn send(&mut self, msg: Msg) -> bool {
        // Never blocks: at most BUFFERS messages exist, and the queue holds that many.
        match self.to.as_ref().map(|to| to.try_send(msg)) {
            Some(Ok(())) => true,
            Some(Err(e)) => {
                let (crossbeam::channel::TrySendError::Full(m) | crossbeam::channel::TrySendError::Disconnected(m)) = e;
                self.keep(m);
                false
            }
            None => false,
        }
    }

    fn keep(&mut self, msg: Msg) {
        let (Msg::Background(pair) | Msg::Frame { pair, .. }) = msg;
        self.spare.push(pair);
    }

    /// Takes whatever came back, without waiting.
    fn drain(&mut self) {
        while let Ok((result, pair)) = self.from.try_recv() {
            self.spare.push(pair);
            if let Some(r) = result {
                self.early.push_back(r);
            }
        }
    }

    /// The oldest pending frame's result on frame `frame_index`: `None` before
    /// [`GESTURE_DELAY_FRAMES`] have passed since it was handed over, or while the thread is
    /// still at it (after waiting up to `due_wait` for it).
    pub fn poll(&mut self, frame_index: u64) -> Option<GestureResult> {
        let &oldest = self.pending.front()?;
        if frame_index < oldest + GESTURE_DELAY_FRAMES {
            return None;
        }
        self.drain();
        if self.early.is_empty() && !self.due_wait.is_zero() {
            let deadline = Instant::now() + self.due_wait;
            while self.early.is_empty() {
                let Ok((result, pair)) = self.from.recv_deadline(deadline) else { break };
                self.spare.push(pair);
                self.early.extend(result);
            }
        }
        let r = self.early.pop_front()?;
        self.pending.pop_front();
        Some(r)
    }
}

impl Drop for GestureThread {
    fn drop(&mut self) {
        self.to = None; // the thread's loop ends
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_vision::pointing::{GestureConfig, PlaneHomography, Pointing};

    fn tracker() -> PointingTracker {
        let plane = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let px = [[10.0, 10.0], [50.0, 10.0], [50.0, 50.0], [10.0, 50.0]];
        let h = PlaneHomography::fit(&plane, &px).unwrap();
        PointingTracker::new(Pointing::new(h.clone(), h), GestureConfig::default())
    }

    #[test]
    fn results_come_in_order_no_earlier_than_the_delay_and_a_due_one_is_waited_for() {
        let img = ImageBuf::filled(64, 48, 40);
        let mut t = GestureThread::spawn(tracker(), 64, 48, Duration::from_secs(5)).unwrap();
        assert!(t.set_background(&img.view(), &img.view()));
        for k in 0..20u64 {
            if k >= GESTURE_DELAY_FRAMES {
                // Due: waited for on this very frame, whatever the thread's speed.
                let r = t.poll(k).expect("a due result is waited for");
                assert_eq!(r.frame_index, k - GESTURE_DELAY_FRAMES);
                assert_eq!(r.frame_id, 100 + k - GESTURE_DELAY_FRAMES);
                assert_eq!(r.state, GestureState::Absent, "nothing changed against the background");
            } else {
                assert_eq!(t.poll(k), None, "early");
            }
            assert!(t.submit(k, 100 + k, &img.view(), &img.view()), "frame {k}: a buffer is free in lockstep");
        }
    }

    #[test]
    fn without_the_wait_frames_are_skipped_rather_than_the_loop_held() {
        let img = ImageBuf::filled(64, 48, 40);
        let mut t = GestureThread::spawn(tracker(), 64, 48, Duration::ZERO).unwrap();
        // Nothing taken back: after BUFFERS frames every buffer is in flight or waiting.
        let handed = (0..10u64).filter(|&k| t.submit(k, k, &img.view(), &img.view())).count();
        assert_eq!(handed, BUFFERS);
        std::thread::sleep(Duration::from_millis(50));
        assert_eq!(t.poll(20).map(|r| r.frame_index), Some(0));
        assert!(t.submit(21, 21, &img.view(), &img.view()));
    }
}
