//! A worker thread for work that may take longer than a frame (gripper location over whole
//! frames, the calibration fit, report images; the grasp planner later). The hard loop hands
//! jobs over a bounded crossbeam channel with `try_send` and collects results with
//! `try_recv`: neither ever blocks, so the loop keeps tracking and answering every frame
//! while the worker computes. A full queue refuses the job (the caller keeps it and tries
//! again next cycle) instead of waiting.
//!
//! ```
//! use handeye_daemon::worker::Worker;
//! let mut worker = Worker::spawn("square", 1, |x: u64| x * x).unwrap();
//! worker.try_submit(7).unwrap();
//! let result = loop {
//!     if let Some(r) = worker.try_result() { break r; }
//!     std::thread::yield_now(); // a real loop would track the next frame here
//! };
//! assert_eq!(result, 49);
//! ```

use std::thread::JoinHandle;
use std::time::Duration;

use crossbeam::channel::{bounded, Receiver, Sender, TryRecvError, TrySendError};

/// A named thread that turns jobs `J` into results `R`, one at a time, in order.
pub struct Worker<J: Send + 'static, R: Send + 'static> {
    jobs: Option<Sender<J>>,
    results: Receiver<R>,
    submitted: u64,
    received: u64,
    handle: Option<JoinHandle<()>>,
    /// How long a caller whose result is due may wait for it (zero: never).
    due_wait: Duration,
}

impl<J: Send + 'static, R: Send + 'static> Worker<J, R> {
    /// Starts the thread. `capacity` jobs may wait in the queue (>= 1); results queue
    /// without bound (the loop drains them every cycle).
    pub fn spawn(name: &str, capacity: usize, mut work: impl FnMut(J) -> R + Send + 'static) -> std::io::Result<Self> {
        let (jobs, job_rx) = bounded::<J>(capacity.max(1));
        let (result_tx, results) = crossbeam::channel::unbounded::<R>();
        let handle = std::thread::Builder::new().name(name.to_string()).spawn(move || {
            for job in job_rx.iter() {
                if result_tx.send(work(job)).is_err() {
                    break; // the owner is gone
                }
            }
        })?;
        Ok(Self { jobs: Some(jobs), results, submitted: 0, received: 0, handle: Some(handle), due_wait: Duration::ZERO })
    }

    /// Queues `job` without waiting; gives it back when the queue is full (or the thread died).
    pub fn try_submit(&mut self, job: J) -> Result<(), J> {
        let Some(tx) = self.jobs.as_ref() else { return Err(job) };
        match tx.try_send(job) {
            Ok(()) => {
                self.submitted += 1;
                Ok(())
            }
            Err(TrySendError::Full(j) | TrySendError::Disconnected(j)) => Err(j),
        }
    }

    /// Whether [`Self::try_submit`] would find room in the queue now: a caller that cannot
    /// rebuild its job checks first instead of losing it to a refusal.
    pub fn has_room(&self) -> bool {
        self.jobs.as_ref().is_some_and(|tx| !tx.is_full())
    }

    /// The next finished result, if any, without waiting.
    pub fn try_result(&mut self) -> Option<R> {
        match self.results.try_recv() {
            Ok(r) => {
                self.received += 1;
                Some(r)
            }
            Err(TryRecvError::Empty | TryRecvError::Disconnected) => None,
        }
    }

    /// The next finished result, waiting up to `timeout` for it. Only for a loop that may
    /// block (lockstep, see [`Self::due_wait`]).
    pub fn wait_result(&mut self, timeout: Duration) -> Option<R> {
        let r = self.results.recv_timeout(timeout).ok()?;
        self.received += 1;
        Some(r)
    }

    /// How long a caller whose result is due may block for it (`timing.worker_wait_ms`;
    /// zero: never).
    pub fn due_wait(&self) -> Duration {
        self.due_wait
    }

    pub fn set_due_wait(&mut self, wait: Duration) {
        self.due_wait = wait;
    }

    /// Jobs submitted whose results have not been collected yet.
    pub fn in_flight(&self) -> u64 {
        self.submitted - self.received
    }

    /// Whether the worker is (or will be) computing something.
    pub fn busy(&self) -> bool {
        self.in_flight() > 0
    }

    /// Whether a job is queued or being computed now (submitted, its result not yet
    /// produced). Unlike [`Self::busy`], a finished result waiting to be collected does not
    /// count: this is what telemetry's `planning` flag shows.
    pub fn computing(&self) -> bool {
        self.in_flight() > self.results.len() as u64
    }

    /// Waits for every queued job to finish and returns their results (for shutdown, never
    /// from the hard loop).
    pub fn finish(mut self) -> Vec<R> {
        self.jobs = None;
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
        self.results.try_iter().collect()
    }
}

impl<J: Send + 'static, R: Send + 'static> Drop for Worker<J, R> {
    fn drop(&mut self) {
        self.jobs = None;
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crossbeam::channel::unbounded;

    #[test]
    fn a_busy_worker_never_blocks_the_caller() {
        // The job waits until the test releases it: if submitting or polling blocked, this
        // test could never reach the release and would hang instead of passing.
        let (release_tx, release_rx) = unbounded::<()>();
        let mut w = Worker::spawn("slow", 1, move |x: u32| {
            let _ = release_rx.recv();
            x + 1
        })
        .unwrap();
        w.try_submit(1).unwrap(); // taken by the thread (or queued)
        // Fill the queue: at most one more fits, then submissions are refused, not blocked.
        let mut refused = 0;
        for i in 0..10 {
            if w.try_submit(10 + i).is_err() {
                refused += 1;
            }
        }
        assert!(refused >= 8, "a full queue must refuse jobs, refused {refused}");
        for _ in 0..1000 {
            assert_eq!(w.try_result(), None, "nothing can be done before the release");
        }
        assert!(w.busy() && w.computing());
        let accepted = w.in_flight();
        for _ in 0..accepted {
            release_tx.send(()).unwrap();
        }
        let mut results = Vec::new();
        while results.len() < accepted as usize {
            if let Some(r) = w.try_result() {
                results.push(r);
            }
            std::thread::yield_now();
        }
        assert_eq!(results[0], 2, "jobs finish in order");
        assert!(!w.busy() && !w.computing());
    }

    #[test]
    fn a_finished_result_waiting_to_be_collected_is_not_computing() {
        let mut w = Worker::spawn("double", 1, |x: u32| 2 * x).unwrap();
        w.try_submit(4).unwrap();
        while w.computing() {
            std::thread::yield_now();
        }
        assert!(w.busy(), "the result is not collected yet");
        assert_eq!(w.try_result(), Some(8));
        assert!(!w.busy());
    }

    #[test]
    fn finish_returns_the_outstanding_results() {
        let mut w = Worker::spawn("double", 4, |x: u32| 2 * x).unwrap();
        for x in 1..=3 {
            w.try_submit(x).unwrap();
        }
        assert_eq!(w.finish(), vec![2, 4, 6]);
    }
}
