//! What the batch commands (`resect`, `detect`) share: the error line of a
//! failed input, loading a frame checked against the camera, the exit
//! status of a batch (docs/conventions.md: non-zero if any input failed),
//! and the parallel run of a batch of image files ([`image_lines`]: workers
//! with their own locator and reused image buffers, lines in input order).

use anyhow::Result;
use photopose_formats::ImageReader;
use photopose_frame::Image;
use photopose_geometry::Camera;
use serde::Serialize;
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc;

/// The output line of a failed input.
#[derive(Serialize)]
pub struct ErrorLine<'a> {
    /// The input path.
    pub image: &'a str,
    /// Always false.
    pub ok: bool,
    /// What and why.
    pub error: String,
}

impl<'a> ErrorLine<'a> {
    /// The line for `image` failing with `error`.
    pub fn new(image: &'a str, error: String) -> Self {
        ErrorLine {
            image,
            ok: false,
            error,
        }
    }
}

/// Loads an image file of the camera's sensor size (checked from the
/// file's header before any pixel is decoded); the error names the file.
pub fn load_frame(path: &Path, camera: &Camera) -> Result<Image, String> {
    photopose_formats::load_image_for(path, camera).map_err(|e| e.to_string())
}

/// The exit status of a batch with `failed` failed inputs.
pub fn exit_status(failed: usize) -> ExitCode {
    if failed > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    }
}

/// Most worker threads of a batch (each holds a locator and a frame's
/// buffers).
const MAX_WORKERS: usize = 4;

/// The worker threads for a batch of `inputs` image files: one per core,
/// at most [`MAX_WORKERS`] and at most one per input.
pub fn workers_for(inputs: usize) -> usize {
    std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(MAX_WORKERS)
        .min(inputs)
        .max(1)
}

/// One output line of an input, and whether the input failed.
pub type Line = (String, bool);

/// Runs a batch of image files (no recordings) on `workers` threads and
/// writes one line per input to `out`, in input order: the same lines as
/// one input after the other, as every input is processed on its own.
/// Each worker makes its state once with `init` (a locator) and reads its
/// files with an [`ImageReader`] (the file's bytes and the raster go into
/// buffers reused from the worker's previous file, so a batch costs no
/// fresh pages per frame); `line` turns an input (its name and its frame,
/// or why it could not be read) into its line. Returns the number of
/// failed inputs; an error of `init`, `line` or writing ends the batch
/// after the lines before it.
pub fn image_lines<S>(
    paths: &[PathBuf],
    camera: &Camera,
    workers: usize,
    init: impl Fn() -> Result<S> + Sync,
    line: impl Fn(&mut S, &str, Result<&Image, String>) -> Result<Line> + Sync,
    out: &mut dyn Write,
) -> Result<usize> {
    let next = AtomicUsize::new(0);
    let stop = AtomicBool::new(false);
    let workers = workers.clamp(1, paths.len().max(1));
    // Bounded: a worker that runs ahead waits for the output.
    let (tx, rx) = mpsc::sync_channel::<(usize, Result<Line>)>(4 * workers);
    std::thread::scope(|scope| -> Result<usize> {
        for _ in 0..workers {
            let tx = tx.clone();
            let (next, stop, init, line) = (&next, &stop, &init, &line);
            scope.spawn(move || {
                let mut reader = ImageReader::for_camera(camera);
                let mut state = None;
                while !stop.load(Ordering::Relaxed) {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(path) = paths.get(i) else { break };
                    let result = match &mut state {
                        Some(s) => Ok(s),
                        None => init().map(|s| state.insert(s)),
                    }
                    .and_then(|s| {
                        let name = path.display().to_string();
                        let frame = reader.load(path).map_err(|e| e.to_string());
                        let l = line(s, &name, frame.as_ref().map_err(String::clone));
                        if let Ok(image) = frame {
                            reader.recycle(image);
                        }
                        l
                    });
                    if tx.send((i, result)).is_err() {
                        break;
                    }
                }
            });
        }
        drop(tx);
        let mut failed = 0;
        let mut pending = BTreeMap::new();
        let mut written = 0;
        let mut end = Ok(());
        for (i, result) in rx.iter() {
            pending.insert(i, result);
            while let Some(result) = pending.remove(&written) {
                written += 1;
                let step = result.and_then(|(text, bad)| {
                    failed += bad as usize;
                    writeln!(out, "{text}")?;
                    Ok(())
                });
                if let Err(e) = step {
                    end = Err(e);
                    break;
                }
            }
            if end.is_err() {
                // The workers stop at their next input (or send).
                stop.store(true, Ordering::Relaxed);
                break;
            }
        }
        drop(rx);
        end.map(|()| failed)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> Camera {
        photopose_formats::default_camera()
    }

    /// Inputs that cannot be read (no such files): each worker's `line`
    /// takes a different time, the lines still come in input order.
    #[test]
    fn lines_come_in_input_order_whatever_the_workers_take() {
        let paths: Vec<PathBuf> = (0..40)
            .map(|i| PathBuf::from(format!("/nonexistent/photopose-batch-{i}.pgm")))
            .collect();
        for workers in [1, 2, 3] {
            let mut out = Vec::new();
            let failed = image_lines(
                &paths,
                &camera(),
                workers,
                || Ok(0usize),
                |calls, name, frame| {
                    *calls += 1;
                    let i: u64 = name
                        .trim_start_matches("/nonexistent/photopose-batch-")
                        .trim_end_matches(".pgm")
                        .parse()?;
                    std::thread::sleep(std::time::Duration::from_micros(300 * (i * 7 % 5)));
                    assert!(frame.unwrap_err().contains(name));
                    Ok((name.to_string(), i.is_multiple_of(4)))
                },
                &mut out,
            )
            .unwrap();
            assert_eq!(failed, 10);
            let want: String = paths.iter().map(|p| format!("{}\n", p.display())).collect();
            assert_eq!(String::from_utf8(out).unwrap(), want, "{workers} workers");
        }
    }

    #[test]
    fn an_error_ends_the_batch_after_the_lines_before_it() {
        let paths: Vec<PathBuf> = (0..30)
            .map(|i| PathBuf::from(format!("/nonexistent/{i}")))
            .collect();
        let mut out = Vec::new();
        let r = image_lines(
            &paths,
            &camera(),
            2,
            || Ok(()),
            |(), name, _| {
                if name == "/nonexistent/7" {
                    anyhow::bail!("seven");
                }
                Ok((name.to_string(), false))
            },
            &mut out,
        );
        assert_eq!(r.unwrap_err().to_string(), "seven");
        let want: String = (0..7).map(|i| format!("/nonexistent/{i}\n")).collect();
        assert_eq!(String::from_utf8(out).unwrap(), want);
        // A failing set-up likewise.
        let mut out = Vec::new();
        let r = image_lines(
            &paths,
            &camera(),
            2,
            || -> Result<()> { anyhow::bail!("no locator") },
            |(), name, _| Ok((name.to_string(), false)),
            &mut out,
        );
        assert_eq!(r.unwrap_err().to_string(), "no locator");
        assert!(out.is_empty());
    }
}
