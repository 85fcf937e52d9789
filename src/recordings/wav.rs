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

/// Recordings of one segment may differ in length by this much (s) and are then cut to the
/// shortest: recorders started together stop within a fraction of a second of each other. A
/// larger difference means the files were not recorded together, and cutting them would
/// analyse different moments as one.
pub const LENGTH_TOLERANCE_S: f64 = 0.5;

/// Frames to reserve for a file whose header claims `header_frames` of `bytes_per_frame`
/// bytes each: never more than the file's `file_bytes` can hold, so a header that overstates
/// the length (4 GB claimed by a file of a few kB) cannot make the reservation exhaust memory.
pub fn reserve_frames(header_frames: u64, file_bytes: u64, bytes_per_frame: u64) -> usize {
    let fits = file_bytes / bytes_per_frame.max(1);
    usize::try_from(header_frames.min(fits)).unwrap_or(0)
}

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
        let file_bytes = std::fs::metadata(&sensor.path).map_or(0, |m| m.len());
        let spec = reader.spec();
        let n_ch = spec.channels as usize;
        if spec.sample_rate == 0 {
            return Err(wav_err(
                sensor.line,
                "its header gives a sample rate of 0 Hz; the file is damaged or not a recording"
                    .into(),
            ));
        }
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
        // The header's length is only a claim: the reservation is bounded by what the file
        // can hold, and reading stops where the samples do.
        let frames = reserve_frames(
            u64::from(reader.duration()),
            file_bytes,
            u64::from(spec.bits_per_sample.div_ceil(8)) * n_ch as u64,
        );
        for &(i, _) in &wanted {
            channels[i] = Vec::with_capacity(frames);
        }
        let mut not_finite: Option<(usize, usize)> = None; // (frame, channel)
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
                    if !x.is_finite()
                        && not_finite.is_none()
                        && wanted.iter().any(|w| w.1 == pos % n_ch)
                    {
                        not_finite = Some((frame, pos % n_ch));
                    }
                    consume!(x, x.abs() >= 1.0);
                }
                if let Some((at, ch)) = not_finite {
                    {
                        return Err(wav_err(
                            sensor.line,
                            format!(
                                "channel {ch} holds samples that are not numbers (NaN or \
                                 infinite), the first at {} s; the recorder or a conversion \
                                 wrote them",
                                short(at as f64 / spec.sample_rate as f64)
                            ),
                        ));
                    }
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
    let longest = channels.iter().map(Vec::len).max().unwrap_or(0);
    if longest - n > (LENGTH_TOLERANCE_S * f64::from(sample_rate)) as usize {
        let at = |len: usize| channels.iter().position(|c| c.len() == len).unwrap_or(0);
        let (short_i, long_i) = (at(n), at(longest));
        let fs = f64::from(sample_rate);
        return Err(RecordingError::Wav {
            segment_id: seg.segment_id.clone(),
            wav: seg.sensors[short_i].path.clone(),
            layout: layout_path.to_path_buf(),
            line: seg.sensors[short_i].line,
            message: format!(
                "the recordings of one segment differ in length: this one is {} s, {} (line {}) \
                 is {} s; the channels must be recorded together (start and stop at once), or \
                 cut to the common part before the analysis",
                short(n as f64 / fs),
                seg.sensors[long_i].file,
                seg.sensors[long_i].line,
                short(longest as f64 / fs)
            ),
        });
    }
    for c in &mut channels {
        c.truncate(n);
    }
    Ok(SegmentAudio {
        sample_rate,
        channels,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reservation_never_exceeds_what_the_file_holds() {
        // An 8-bit mono file of 1000 bytes whose header claims 4 GB of samples.
        assert_eq!(reserve_frames(4_000_000_000, 1000, 1), 1000);
        // 16-bit stereo: 4 bytes a frame.
        assert_eq!(reserve_frames(u64::from(u32::MAX), 4000, 4), 1000);
        // A truthful header is taken as it is.
        assert_eq!(reserve_frames(100, 1_000_000, 2), 100);
        // A header without a frame size cannot divide by zero.
        assert_eq!(reserve_frames(7, 10, 0), 7);
    }
}
