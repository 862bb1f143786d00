//! Work longer than a frame, on the [`crate::worker`] thread, typed: a phase hands over a
//! closure and gets a [`PendingJob`] that yields exactly what that closure returns. Each job
//! carries its own reply channel, so no phase ever sees another phase's result.
//!
//! A result is taken no earlier than [`WORKER_DELAY_FRAMES`] after submission, on the first
//! frame at or after that when it is there: a fixed pipeline delay keeps lockstep runs
//! repeatable, the worker's wall-clock speed never decides on which frame the loop moves on.
//! When the result is due but not there (a loaded machine), a lockstep daemon
//! (`timing.worker_wait_ms`) waits for it on that frame, so that it still does not.

use crossbeam::channel::{bounded, Receiver};

use crate::worker::Worker;

/// Frames after submission at which a worker result is taken (it waits if it is early).
/// 1 s at 30 frames/s is far more than any job needs, and the loop keeps tracking and
/// answering frames meanwhile.
pub const WORKER_DELAY_FRAMES: u64 = 30;

/// One job for the worker thread: it computes and sends its result to its [`PendingJob`].
pub struct Job(Box<dyn FnOnce() + Send>);

/// The worker thread of the phases. Its own result is only the news that a job finished
/// (it keeps the worker's `busy` count, which telemetry shows); the value travels on the
/// job's own channel.
pub type JobWorker = Worker<Job, ()>;

/// Starts the phases' worker thread.
pub fn spawn_worker() -> std::io::Result<JobWorker> {
    Worker::spawn("handeye-worker", 2, |job: Job| (job.0)())
}

/// A job handed to the worker, whose result of type `T` is to be taken.
pub struct PendingJob<T> {
    submitted_frame: u64,
    reply: Receiver<T>,
    collected: Option<T>,
}

impl<T: Send + 'static> PendingJob<T> {
    /// Hands `work` to the worker on frame `frame_index`; `None` when the worker refused it
    /// (its queue is full, or it died): the caller tries again on a later frame.
    pub fn submit(worker: &mut JobWorker, frame_index: u64, work: impl FnOnce() -> T + Send + 'static) -> Option<Self> {
        let (tx, reply) = bounded(1);
        let job = Job(Box::new(move || {
            // The phase may have gone (the run ended): nobody to tell.
            let _ = tx.send(work());
        }));
        worker.try_submit(job).ok().map(|()| Self { submitted_frame: frame_index, reply, collected: None })
    }

    /// The frame on which the job was handed over.
    pub fn submitted_frame(&self) -> u64 {
        self.submitted_frame
    }

    /// Takes a finished result off the worker now, before it is due (the worker then no
    /// longer counts as busy); it is still handed out no earlier than [`Self::poll`] allows.
    pub fn collect(&mut self, worker: &mut JobWorker) {
        // The job sent its value before the worker reported it done.
        if self.collected.is_none() && worker.try_result().is_some() {
            self.collected = self.reply.try_recv().ok();
        }
    }

    /// A result collected early and not yet handed out.
    pub fn collected(&self) -> Option<&T> {
        self.collected.as_ref()
    }

    /// The result, on frame `frame_index`: `None` before [`WORKER_DELAY_FRAMES`] have passed
    /// since submission, or while the worker is still at it (after waiting up to the worker's
    /// [`due_wait`](crate::worker::Worker::due_wait) for it).
    pub fn poll(&mut self, worker: &mut JobWorker, frame_index: u64) -> Option<T> {
        if frame_index < self.submitted_frame + WORKER_DELAY_FRAMES {
            return None;
        }
        self.collect(worker);
        if self.collected.is_none()
            && !worker.due_wait().is_zero()
            && let Ok(value) = self.reply.recv_timeout(worker.due_wait())
        {
            self.collected = Some(value);
            // The worker reports the job done just after the job sent its value.
            let _ = worker.wait_result(worker.due_wait());
        }
        self.collected.take()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_result_is_handed_out_no_earlier_than_the_delay() {
        let mut worker = spawn_worker().unwrap();
        let mut job = PendingJob::submit(&mut worker, 10, || 6 * 7).unwrap();
        while worker.computing() {
            std::thread::yield_now();
        }
        assert_eq!(job.poll(&mut worker, 10 + WORKER_DELAY_FRAMES - 1), None, "early");
        assert!(worker.busy(), "not collected before it is due");
        assert_eq!(job.poll(&mut worker, 10 + WORKER_DELAY_FRAMES), Some(42));
        assert!(!worker.busy());
    }

    #[test]
    fn a_lockstep_loop_waits_for_a_late_result_on_the_frame_it_is_due() {
        let mut worker = spawn_worker().unwrap();
        worker.set_due_wait(std::time::Duration::from_secs(5));
        let mut job = PendingJob::submit(&mut worker, 0, || {
            std::thread::sleep(std::time::Duration::from_millis(200));
            7
        })
        .unwrap();
        // Due, still computing: waited for, not put off to a later frame.
        assert_eq!(job.poll(&mut worker, WORKER_DELAY_FRAMES), Some(7));
        assert!(!worker.busy());
        // Without the wait the same late result is not there on its frame.
        let mut worker = spawn_worker().unwrap();
        let mut job = PendingJob::submit(&mut worker, 0, || {
            std::thread::sleep(std::time::Duration::from_millis(200));
            7
        })
        .unwrap();
        assert_eq!(job.poll(&mut worker, WORKER_DELAY_FRAMES), None);
    }

    #[test]
    fn collecting_early_frees_the_worker_but_keeps_the_result_until_due() {
        let mut worker = spawn_worker().unwrap();
        let mut job = PendingJob::submit(&mut worker, 0, || String::from("plates")).unwrap();
        while job.collected().is_none() {
            job.collect(&mut worker);
            std::thread::yield_now();
        }
        assert!(!worker.busy());
        assert_eq!(job.poll(&mut worker, 1), None);
        assert_eq!(job.poll(&mut worker, WORKER_DELAY_FRAMES).as_deref(), Some("plates"));
    }
}
