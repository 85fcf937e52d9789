//! The layout file of a hydrant test (docs/interface.md, `pipewave wavenumbers`): one row per
//! sensor, `segment_id, file, channel, position_m`, the WAV file relative to the layout's folder,
//! its channel from 0, and the sensor's signed position along the pipe in metres from the noise
//! source.

use std::path::{Path, PathBuf};

use super::{short, RecordingError};

/// The columns a layout file must have.
pub const LAYOUT_COLUMNS: [&str; 4] = ["segment_id", "file", "channel", "position_m"];

/// One sensor: where it is and where its signal is.
#[derive(Debug, Clone, PartialEq)]
pub struct Sensor {
    /// Line of the layout file that describes it (1 = header).
    pub line: u64,
    /// The WAV file as written in the layout.
    pub file: String,
    /// The WAV file, resolved against the layout's folder.
    pub path: PathBuf,
    /// Channel number in the file, from 0.
    pub channel: u16,
    /// Signed position along the pipe, m from the noise source.
    pub position_m: f64,
}

impl Sensor {
    /// Distance from the source |x|, m.
    pub fn distance_m(&self) -> f64 {
        self.position_m.abs()
    }
}

/// The sensors of one pipe segment, in layout order.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentLayout {
    /// Asset id.
    pub segment_id: String,
    /// Its sensors.
    pub sensors: Vec<Sensor>,
}

impl SegmentLayout {
    /// The layout of one multichannel file `file` whose channel c sits at `positions_m[c]`,
    /// as a layout file of one row per channel would give it (lines from 2).
    pub fn one_file(segment_id: &str, file: &str, positions_m: &[f64]) -> SegmentLayout {
        SegmentLayout {
            segment_id: segment_id.to_string(),
            sensors: positions_m
                .iter()
                .enumerate()
                .map(|(c, &x)| Sensor {
                    line: c as u64 + 2,
                    file: file.to_string(),
                    path: PathBuf::from(file),
                    channel: c as u16,
                    position_m: x,
                })
                .collect(),
        }
    }
}

/// A checked layout file.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// The layout file.
    pub path: PathBuf,
    /// Segments in order of first appearance.
    pub segments: Vec<SegmentLayout>,
}

/// Read and check a layout file. Every bad cell is reported (one error each); the file is used
/// only when all rows are valid.
pub fn read_layout(path: &Path) -> Result<Layout, Vec<RecordingError>> {
    let io = |e: &dyn std::fmt::Display| {
        vec![RecordingError::Io {
            path: path.to_path_buf(),
            message: e.to_string(),
        }]
    };
    let text = std::fs::read(path).map_err(|e| io(&e))?;
    let mut rdr = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .flexible(true)
        .from_reader(text.as_slice());
    let headers = rdr.headers().map_err(|e| io(&e))?.clone();
    let mut idx = [0usize; 4];
    let mut missing = Vec::new();
    for (k, name) in LAYOUT_COLUMNS.iter().enumerate() {
        match headers.iter().position(|h| h.eq_ignore_ascii_case(name)) {
            Some(i) => idx[k] = i,
            None => missing.push(*name),
        }
    }
    if !missing.is_empty() {
        return Err(vec![RecordingError::LayoutFile {
            file: path.to_path_buf(),
            message: format!(
                "missing column{} {} (a layout needs {})",
                if missing.len() == 1 { "" } else { "s" },
                missing.join(", "),
                LAYOUT_COLUMNS.join(", ")
            ),
        }]);
    }
    let folder = path.parent().unwrap_or(Path::new("")).to_path_buf();
    let mut errors = Vec::new();
    let mut segments: Vec<SegmentLayout> = Vec::new();
    let cell_err = |line: u64, column: &str, message: String| RecordingError::Layout {
        file: path.to_path_buf(),
        line,
        column: column.to_string(),
        message,
    };
    for rec in rdr.records() {
        let rec = match rec {
            Ok(r) => r,
            Err(e) => {
                let line = e.position().map(|p| p.line()).unwrap_or(0);
                errors.push(cell_err(line, "-", format!("unreadable row: {e}")));
                continue;
            }
        };
        let line = rec.position().map(|p| p.line()).unwrap_or(0);
        if rec.iter().all(str::is_empty) {
            continue;
        }
        let get = |k: usize| rec.get(idx[k]).unwrap_or("");
        let mut ok = true;
        let segment_id = get(0).to_string();
        if segment_id.is_empty() {
            errors.push(cell_err(
                line,
                "segment_id",
                "empty (expected the pipe's asset id)".into(),
            ));
            ok = false;
        }
        let file = get(1).to_string();
        if file.is_empty() {
            errors.push(cell_err(
                line,
                "file",
                "empty (expected a WAV file relative to the layout's folder)".into(),
            ));
            ok = false;
        }
        let channel = match get(2).parse::<u16>() {
            Ok(c) => c,
            Err(_) => {
                errors.push(cell_err(
                    line,
                    "channel",
                    format!("'{}' is not a channel number (0, 1, 2, ... from the first channel of the file)", get(2)),
                ));
                ok = false;
                0
            }
        };
        let position_m = match get(3).parse::<f64>() {
            Ok(x) if x.is_finite() => x,
            Ok(x) => {
                errors.push(cell_err(
                    line,
                    "position_m",
                    format!(
                        "{} is not a position (expected signed metres from the source)",
                        short(x)
                    ),
                ));
                ok = false;
                0.0
            }
            Err(_) => {
                errors.push(cell_err(
                    line,
                    "position_m",
                    format!(
                        "'{}' is not a number (expected signed metres from the source)",
                        get(3)
                    ),
                ));
                ok = false;
                0.0
            }
        };
        if !ok {
            continue;
        }
        let sensor = Sensor {
            line,
            path: folder.join(&file),
            file,
            channel,
            position_m,
        };
        match segments.iter_mut().find(|s| s.segment_id == segment_id) {
            Some(s) => s.sensors.push(sensor),
            None => segments.push(SegmentLayout {
                segment_id,
                sensors: vec![sensor],
            }),
        }
    }
    for seg in &segments {
        check_segment(path, seg, &mut errors);
    }
    if segments.is_empty() && errors.is_empty() {
        errors.push(RecordingError::LayoutFile {
            file: path.to_path_buf(),
            message: "no sensors (expected one row per sensor)".into(),
        });
    }
    if errors.is_empty() {
        Ok(Layout {
            path: path.to_path_buf(),
            segments,
        })
    } else {
        Err(errors)
    }
}

/// The checks that need a segment's rows together: the same channel twice, fewer than two
/// sensors, two sensors on one side at the same distance from the source (zero spacing).
fn check_segment(path: &Path, seg: &SegmentLayout, errors: &mut Vec<RecordingError>) {
    let err = |line: u64, column: &str, message: String| RecordingError::Layout {
        file: path.to_path_buf(),
        line,
        column: column.to_string(),
        message,
    };
    if seg.sensors.len() < 2 {
        errors.push(err(
            seg.sensors[0].line,
            "segment_id",
            format!(
                "segment {} has one sensor; a wavenumber needs two or more on the pipe (three for the noise-robust estimate)",
                seg.segment_id
            ),
        ));
        return;
    }
    for (j, b) in seg.sensors.iter().enumerate() {
        for a in &seg.sensors[..j] {
            if a.file == b.file && a.channel == b.channel {
                errors.push(err(
                    b.line,
                    "channel",
                    format!(
                        "segment {}: {} channel {} is already used for the sensor of line {}",
                        seg.segment_id, b.file, b.channel, a.line
                    ),
                ));
            } else if a.distance_m() == b.distance_m()
                && (a.position_m == b.position_m || a.position_m == 0.0 || b.position_m == 0.0)
            {
                errors.push(err(
                    b.line,
                    "position_m",
                    format!(
                        "segment {}: zero distance: position {} m is the same distance from the source, on the same side, as the sensor of line {} ({} m); positions are signed metres from the source, negative on one side",
                        seg.segment_id,
                        short(b.position_m),
                        a.line,
                        short(a.position_m)
                    ),
                ));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(text: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("layout.csv");
        std::fs::write(&p, text).unwrap();
        (dir, p)
    }

    #[test]
    fn reads_and_groups_rows() {
        let (_d, p) = write(
            "segment_id,file,channel,position_m\nA,a.wav,0,0\nA,a.wav,1,-20.5\nB,b.wav,0,0\nA,a.wav,2,31\nB,b.wav,1,12\n",
        );
        let l = read_layout(&p).unwrap();
        assert_eq!(l.segments.len(), 2);
        assert_eq!(l.segments[0].sensors.len(), 3);
        assert_eq!(l.segments[0].sensors[1].position_m, -20.5);
        assert_eq!(l.segments[0].sensors[2].line, 5);
        assert_eq!(
            l.segments[0].sensors[2].path,
            p.parent().unwrap().join("a.wav")
        );
    }

    #[test]
    fn names_line_and_column_of_bad_cells() {
        let (_d, p) = write("segment_id,file,channel,position_m\nA,a.wav,x,0\nA,a.wav,1,far\n");
        let e = read_layout(&p).unwrap_err();
        let text: Vec<String> = e.iter().map(|e| e.to_string()).collect();
        assert!(
            text[0].contains("line 2, column channel") && text[0].contains("'x'"),
            "{text:?}"
        );
        assert!(
            text[1].contains("line 3, column position_m") && text[1].contains("'far'"),
            "{text:?}"
        );
    }

    #[test]
    fn zero_distance_on_one_side_is_an_error_but_mirror_positions_are_not() {
        let (_d, p) =
            write("segment_id,file,channel,position_m\nA,a.wav,0,0\nA,a.wav,1,20\nA,a.wav,2,20\n");
        let e = read_layout(&p).unwrap_err();
        assert!(
            e[0].to_string()
                .contains("line 4, column position_m: segment A: zero distance"),
            "{}",
            e[0]
        );
        let (_d, p) =
            write("segment_id,file,channel,position_m\nA,a.wav,0,0\nA,a.wav,1,20\nA,a.wav,2,-20\n");
        assert!(read_layout(&p).is_ok());
    }

    #[test]
    fn missing_column_is_named() {
        let (_d, p) = write("segment_id,file,position_m\nA,a.wav,0\n");
        let e = read_layout(&p).unwrap_err();
        assert!(
            e[0].to_string().contains("missing column channel"),
            "{}",
            e[0]
        );
    }
}
