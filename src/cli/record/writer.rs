//! The recorder's frame writer: a thread that encodes each kept frame's views as PNG files
//! and appends its `frames.jsonl` line once the files are on disk (a line always names files
//! that exist). The subscriber hands it copies of the pixels through a bounded channel and
//! waits for it only a bounded time: at most `capacity` frame buffers exist, reused round
//! and round, so memory stays bounded; a frame that finds no free buffer within the wait is
//! counted as not kept.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{Context, Result};
use crossbeam::channel::{bounded, Receiver, Sender, TryRecvError};
use handeye_wire::checksum::PixelChecksum;
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, ImageEncoder};

use crate::cli::recording::{FrameRecord, FRAMES_FILE};

/// One kept frame: its `frames.jsonl` line and its views' pixels, tightly packed (left
/// rows, then right rows).
pub struct FrameJob {
    pub record: FrameRecord,
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<u8>,
}

/// What the writer did, when it has finished.
#[derive(Debug, Default)]
pub struct WriterReport {
    pub written: u64,
    /// Frames handed over but not written because an earlier write failed.
    pub failed: u64,
    pub checksum: PixelChecksum,
    /// The first write error: which file, and why.
    pub error: Option<String>,
}

/// The writer thread and the two channels to it: jobs in, empty buffers back.
pub struct FrameWriter {
    jobs: Option<Sender<FrameJob>>,
    free: Receiver<Vec<u8>>,
    allocated: usize,
    capacity: usize,
    failed: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: Option<JoinHandle<WriterReport>>,
}

impl FrameWriter {
    /// Starts the thread writing into `dir` (which holds `left/` and `right/`), with at most
    /// `capacity` frames waiting.
    pub fn start(dir: &Path, capacity: usize) -> Result<Self> {
        let capacity = capacity.max(1);
        let path = dir.join(FRAMES_FILE);
        let lines = BufWriter::new(File::create(&path).with_context(|| format!("cannot create {}", path.display()))?);
        let (jobs, job_rx) = bounded::<FrameJob>(capacity);
        let (free_tx, free) = bounded::<Vec<u8>>(capacity);
        let failed = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let thread = std::thread::Builder::new()
            .name("record-writer".into())
            .spawn({
                let (dir, failed) = (dir.to_path_buf(), failed.clone());
                move || write_frames(&dir, path, lines, job_rx, free_tx, &failed)
            })
            .context("starting the writer thread")?;
        Ok(Self { jobs: Some(jobs), free, allocated: 0, capacity, failed, thread: Some(thread) })
    }

    /// An empty buffer for the next frame: a free one, a new one while fewer than
    /// `capacity` exist, or else the first one the writer frees within `wait`. `None` when
    /// the writer stays behind that long.
    pub fn buffer(&mut self, wait: Duration) -> Option<Vec<u8>> {
        match self.free.try_recv() {
            Ok(b) => Some(b),
            Err(TryRecvError::Empty | TryRecvError::Disconnected) if self.allocated < self.capacity => {
                self.allocated += 1;
                Some(Vec::new())
            }
            Err(_) => self.free.recv_timeout(wait).ok(),
        }
    }

    /// Queues a frame; never blocks (a job always has a buffer from [`Self::buffer`], and
    /// there are no more buffers than queue places).
    pub fn submit(&mut self, job: FrameJob) {
        if let Some(jobs) = &self.jobs {
            // Fails only when the thread has ended, which `failed()` reports.
            let _ = jobs.try_send(job);
        }
    }

    /// Frames waiting to be written.
    pub fn queued(&self) -> usize {
        self.jobs.as_ref().map_or(0, |jobs| jobs.len())
    }

    /// Whether a write has failed (the recording should end).
    pub fn failed(&self) -> bool {
        self.failed.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Writes everything queued, then stops the thread.
    pub fn finish(mut self) -> WriterReport {
        self.jobs = None; // the thread ends when the queue is empty and closed
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(report)) => report,
            _ => WriterReport { error: Some("the writer thread panicked".into()), ..WriterReport::default() },
        }
    }
}

fn write_frames(
    dir: &Path,
    path: PathBuf,
    mut lines: BufWriter<File>,
    jobs: Receiver<FrameJob>,
    free: Sender<Vec<u8>>,
    failed: &std::sync::atomic::AtomicBool,
) -> WriterReport {
    let mut report = WriterReport::default();
    for job in jobs {
        if report.error.is_some() {
            report.failed += 1;
            continue;
        }
        match write_one(dir, &path, &mut lines, &job) {
            Ok(()) => {
                report.written += 1;
                let (w, h) = (job.width as usize, job.height as usize);
                for plane in job.pixels.chunks_exact(w * h) {
                    report.checksum.add_image(plane, w, h, w);
                }
            }
            Err(e) => {
                report.failed += 1;
                report.error = Some(format!("{e:#}"));
                failed.store(true, std::sync::atomic::Ordering::Relaxed);
            }
        }
        let _ = free.try_send(job.pixels);
    }
    if report.error.is_none()
        && let Err(e) = lines.flush()
    {
        report.error = Some(format!("cannot write {}: {e}", path.display()));
    }
    report
}

/// Encodes the views (in parallel: left here, right on a second thread) and appends the line.
fn write_one(dir: &Path, path: &Path, lines: &mut BufWriter<File>, job: &FrameJob) -> Result<()> {
    let plane = job.width as usize * job.height as usize;
    let r = &job.record;
    let left = (dir.join(&r.left), &job.pixels[..plane]);
    let right = r.right.as_ref().map(|name| (dir.join(name), &job.pixels[plane..2 * plane]));
    std::thread::scope(|scope| {
        let right = right.map(|(p, px)| scope.spawn(move || save_png(&p, px, job.width, job.height)));
        save_png(&left.0, left.1, job.width, job.height)?;
        match right.map(|h| h.join()) {
            Some(Ok(result)) => result,
            Some(Err(_)) => anyhow::bail!("the PNG encoder panicked"),
            None => Ok(()),
        }
    })?;
    let line = serde_json::to_string(r).context("encoding a frames.jsonl line")?;
    writeln!(lines, "{line}").with_context(|| format!("cannot write {}", path.display()))
}

/// A GRAY8 PNG, fast compression: the recorder must keep up with a camera.
fn save_png(path: &Path, pixels: &[u8], width: u32, height: u32) -> Result<()> {
    let file = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    PngEncoder::new_with_quality(BufWriter::new(file), CompressionType::Fast, FilterType::Sub)
        .write_image(pixels, width, height, ExtendedColorType::L8)
        .with_context(|| format!("cannot write {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(id: u64, value: u8) -> FrameJob {
        let (left, right) = FrameRecord::file_names(id, 2);
        FrameJob {
            record: FrameRecord {
                id,
                capture_time_ns: 1000 * id,
                publish_time_ns: 1000 * id + 5,
                receive_time_ns: 1000 * id + 9,
                left,
                right,
                missed_before: 0,
                not_kept_before: 0,
            },
            width: 3,
            height: 2,
            pixels: [vec![value; 6], vec![value + 1; 6]].concat(),
        }
    }

    #[test]
    fn frames_become_pngs_and_lines_and_buffers_are_bounded() {
        let dir = std::env::temp_dir().join(format!("handeye-record-writer-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        for sub in ["left", "right"] {
            std::fs::create_dir_all(dir.join(sub)).unwrap();
        }
        let mut w = FrameWriter::start(&dir, 2).unwrap();
        assert!(w.buffer(Duration::ZERO).is_some() && w.buffer(Duration::ZERO).is_some());
        assert!(w.buffer(Duration::from_millis(20)).is_none(), "two buffers exist and both are out");
        w.submit(job(4, 10));
        w.submit(job(6, 20));
        let report = w.finish();
        assert_eq!((report.written, report.failed, report.error), (2, 0, None));
        let png = image::open(dir.join("right/00000006.png")).unwrap().to_luma8();
        assert_eq!((png.dimensions(), png.as_raw().clone()), ((3, 2), vec![21; 6]));
        let text = std::fs::read_to_string(dir.join(FRAMES_FILE)).unwrap();
        let ids: Vec<u64> = text.lines().map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["id"].as_u64().unwrap()).collect();
        assert_eq!(ids, [4, 6]);
        let mut expected = PixelChecksum::new();
        for v in [10u8, 11, 20, 21] {
            expected.add_bytes(&[v; 6]);
        }
        assert_eq!(report.checksum, expected);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_write_error_names_the_file_and_later_frames_are_counted_as_failed() {
        let dir = std::env::temp_dir().join(format!("handeye-record-writer-err-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap(); // no left/ and right/: creating the PNGs fails
        let mut w = FrameWriter::start(&dir, 4).unwrap();
        w.submit(job(0, 1));
        w.submit(job(1, 1));
        let report = w.finish();
        assert_eq!((report.written, report.failed), (0, 2));
        let err = report.error.unwrap();
        assert!(err.contains("00000000.png"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
