//! Reading the sensor channels of a segment from WAV files (hound): 8/16/24/32-bit PCM and
//! 32-bit float, one or several channels per file, one or several files per segment.
//!
//! Field mistakes are caught here with messages naming the layout line and the WAV file: a
//! channel the file does not have (a mono file where several channels are named), files of one
//! segment at different sample rates, and clipped recordings.

use std::collections::BTreeMap;
use std::path::Path;

use hound::{SampleFormat, WavReader};

use super::layout::SegmentLayout;
use super::{short, RecordingError};

/// Consecutive full-scale samples that mark a clipped recording. A Gaussian-like noise signal
/// below full scale never repeats the extreme code four times in a row; a recorder whose input
/// stage saturates does so on every loud burst.
pub const CLIP_RUN_SAMPLES: usize = 4;

/// The channels of one segment, one per sensor in layout order, scaled to full scale = 1.
#[derive(Debug, Clone)]
pub struct SegmentAudio {
    /// Sample rate, Hz.
    pub sample_rate: u32,
    /// One signal per sensor (same length: the shortest file's).
    pub channels: Vec<Vec<f64>>,
}

impl SegmentAudio {
    /// Length of the common record, s.
    pub fn duration_s(&self) -> f64 {
        self.channels.first().map_or(0, Vec::len) as f64 / self.sample_rate as f64
    }
}

/// Frames (samples per channel) in the files of a layout, to size a progress bar; `None` if a
/// header cannot be read (the analysis then reports it).
pub fn total_frames(segments: &[SegmentLayout]) -> Option<u64> {
    let mut total = 0u64;
    for seg in segments {
        let mut seen: Vec<&Path> = Vec::new();
        for s in &seg.sensors {
            if seen.contains(&s.path.as_path()) {
                continue;
            }
            seen.push(&s.path);
            total += WavReader::open(&s.path).ok()?.duration() as u64;
        }
    }
    Some(total)
}

/// Read the channels of a segment's sensors. `progress` is called with the frames read.
pub fn read_segment(
    layout_path: &Path,
    seg: &SegmentLayout,
    progress: &dyn Fn(u64),
) -> Result<SegmentAudio, RecordingError> {
    // Files in order of first use; each is read once for all its sensors.
    let mut files: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    let mut first_of: Vec<usize> = Vec::new();
    for (i, s) in seg.sensors.iter().enumerate() {
        let key = seg.sensors[..i]
            .iter()
            .position(|t| t.path == s.path)
            .unwrap_or(i);
        if key == i {
            first_of.push(i);
        }
        files.entry(key).or_default().push(i);
    }
    let mut channels: Vec<Vec<f64>> = vec![Vec::new(); seg.sensors.len()];
    let mut rate: Option<(u32, usize)> = None;
    for &first in &first_of {
        let sensor = &seg.sensors[first];
        let wav_err = |line: u64, message: String| RecordingError::Wav {
            segment_id: seg.segment_id.clone(),
            wav: sensor.path.clone(),
            layout: layout_path.to_path_buf(),
            line,
            message,
        };
        let mut reader = WavReader::open(&sensor.path)
            .map_err(|e| wav_err(sensor.line, format!("not a readable WAV file ({e})")))?;
        let spec = reader.spec();
        let n_ch = spec.channels as usize;
        for &i in &files[&first] {
            let s = &seg.sensors[i];
            if s.channel as usize >= n_ch {
                let message = if n_ch == 1 {
                    format!(
                        "the file is mono (one channel, number 0) but column channel names channel {}; \
                         was it recorded in mono by mistake, or should each sensor have its own file?",
                        s.channel
                    )
                } else {
                    format!(
                        "missing channel: column channel names channel {} but the file has {} channels (0 - {})",
                        s.channel,
                        n_ch,
                        n_ch - 1
                    )
                };
                return Err(wav_err(s.line, message));
            }
        }
        match rate {
            None => rate = Some((spec.sample_rate, first)),
            Some((r, at)) if r != spec.sample_rate => {
                return Err(wav_err(
                    sensor.line,
                    format!(
                        "sample rate {} Hz, but its partner {} (line {}) is at {} Hz; the channels of one \
                         segment must be recorded at one rate and started together",
                        spec.sample_rate, seg.sensors[at].file, seg.sensors[at].line, r
                    ),
                ));
            }
            _ => {}
        }
        let wanted: Vec<(usize, usize)> = files[&first]
            .iter()
            .map(|&i| (i, seg.sensors[i].channel as usize))
            .collect();
        let frames = reader.duration() as usize;
        for &(i, _) in &wanted {
            channels[i] = Vec::with_capacity(frames);
        }
        // Clipping: a run of full-scale samples, per channel.
        let mut run = vec![0usize; wanted.len()];
        let mut clipped: Vec<Option<(usize, usize)>> = vec![None; wanted.len()]; // (first frame, runs)
        let bits = spec.bits_per_sample;
        let read_err =
            |e: hound::Error| wav_err(sensor.line, format!("cannot read its samples ({e})"));
        let mut frame = 0usize;
        let mut pos = 0usize;
        macro_rules! consume {
            ($x:expr, $full:expr) => {{
                let ch = pos % n_ch;
                if let Some(k) = wanted.iter().position(|w| w.1 == ch) {
                    let v: f64 = $x;
                    channels[wanted[k].0].push(v);
                    if $full {
                        run[k] += 1;
                        if run[k] == CLIP_RUN_SAMPLES {
                            let c = clipped[k].get_or_insert((frame, 0));
                            c.1 += 1;
                        }
                    } else {
                        run[k] = 0;
                    }
                }
                pos += 1;
                if pos % n_ch == 0 {
                    frame += 1;
                    if frame % 65_536 == 0 {
                        progress(65_536);
                    }
                }
            }};
        }
        match spec.sample_format {
            SampleFormat::Float => {
                if bits != 32 {
                    return Err(wav_err(
                        sensor.line,
                        format!(
                            "{bits}-bit float samples (expected 32-bit float or 16/24-bit PCM)"
                        ),
                    ));
                }
                for s in reader.samples::<f32>() {
                    let x = s.map_err(read_err)? as f64;
                    consume!(x, x.abs() >= 1.0);
                }
            }
            SampleFormat::Int => {
                if !(8..=32).contains(&bits) {
                    return Err(wav_err(
                        sensor.line,
                        format!(
                            "{bits}-bit PCM samples (expected 16 or 24-bit PCM, or 32-bit float)"
                        ),
                    ));
                }
                let scale = 2f64.powi(bits as i32 - 1);
                let max = (1i64 << (bits - 1)) - 1;
                for s in reader.samples::<i32>() {
                    let x = s.map_err(read_err)? as i64;
                    consume!(x as f64 / scale, x >= max || x <= -max);
                }
            }
        }
        progress((frame % 65_536) as u64);
        for (k, &(i, ch)) in wanted.iter().enumerate() {
            if let Some((at, runs)) = clipped[k] {
                return Err(wav_err(
                    seg.sensors[i].line,
                    format!(
                        "clipped recording: channel {ch} has {runs} run{} of {CLIP_RUN_SAMPLES} or more full-scale samples \
                         (the first at {} s); record again with less gain",
                        if runs == 1 { "" } else { "s" },
                        short(at as f64 / spec.sample_rate as f64)
                    ),
                ));
            }
        }
    }
    let sample_rate = rate.map(|r| r.0).unwrap_or(0);
    let n = channels.iter().map(Vec::len).min().unwrap_or(0);
    for c in &mut channels {
        c.truncate(n);
    }
    Ok(SegmentAudio {
        sample_rate,
        channels,
    })
}
