//! The path between two sensors through the pipe network (model §11): the segments' lines in
//! one projected coordinate system, sensors placed by chainage or snapped from map coordinates,
//! a graph of segment end points joined within a tolerance, routing by the shortest length
//! along the geometry, and explicit paths checked for contiguity.

use std::collections::HashMap;

use petgraph::graph::{NodeIndex, UnGraph};
use petgraph::visit::EdgeRef;

use super::LocateError;
use crate::db::crs::{self, ToCommonCrs};
use crate::db::wkt::LineString;
use crate::db::SegmentRecord;

/// Default distance within which two segment end points are the same junction, m.
pub const DEFAULT_JOIN_TOLERANCE_M: f64 = 1.0;
/// Default distance within which map coordinates are snapped to the nearest segment, m.
pub const DEFAULT_SNAP_TOLERANCE_M: f64 = 5.0;
/// Slack on a chainage at a segment's end, m: a sensor at "120 m" on a 119.998 m line is at its
/// end (GIS lengths are rounded); more than this is off the segment.
pub const CHAINAGE_SLACK_M: f64 = 0.05;

/// One segment as the path finder sees it.
#[derive(Debug, Clone)]
pub struct NetSegment {
    /// Asset id.
    pub id: String,
    /// Its line in the network's coordinate system (metres), when it has one.
    pub line: Option<LineString>,
    /// Length, m: along the line, or the inventory's `length_m` without a line.
    pub length_m: Option<f64>,
    /// Cumulative length at each vertex of the line, m.
    cum: Vec<f64>,
    /// Why its stored geometry cannot be used, when it cannot: the segment then has neither a
    /// line nor a length, and every job that needs it fails with this reason.
    pub problem: Option<String>,
}

impl NetSegment {
    /// A segment with its line (in metres) or, without one, its inventory length.
    pub fn new(id: String, line: Option<LineString>, length_m: Option<f64>) -> NetSegment {
        let cum = line.as_ref().map(cumulative).unwrap_or_default();
        let length_m = match &line {
            Some(_) => cum.last().copied(),
            None => length_m.filter(|l| l.is_finite() && *l > 0.0),
        };
        NetSegment {
            id,
            line,
            length_m,
            cum,
            problem: None,
        }
    }

    /// A segment whose stored geometry cannot be used, for `why`: it is in the network (so a
    /// job naming it gets this reason) but has no line, no length and no junctions.
    pub fn unusable(id: String, why: String) -> NetSegment {
        NetSegment {
            problem: Some(why),
            ..NetSegment::new(id, None, None)
        }
    }

    /// `Err` naming the segment when its geometry cannot be used.
    fn usable(&self) -> Result<(), LocateError> {
        match &self.problem {
            Some(why) => Err(LocateError::Network(format!(
                "segment {}: its stored geometry cannot be used ({why}); correct it and \
                 re-import the segment to locate on it",
                self.id
            ))),
            None => Ok(()),
        }
    }

    /// The map point at `chainage` m from the first vertex (clamped to the line).
    pub fn point_at(&self, chainage: f64) -> Option<(f64, f64)> {
        let line = self.line.as_ref()?;
        let c = chainage.clamp(0.0, *self.cum.last()?);
        let i = self
            .cum
            .partition_point(|&v| v < c)
            .clamp(1, self.cum.len() - 1);
        let (a, b) = (line.points[i - 1], line.points[i]);
        let span = self.cum[i] - self.cum[i - 1];
        let t = if span > 0.0 {
            (c - self.cum[i - 1]) / span
        } else {
            0.0
        };
        Some((a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1)))
    }

    /// The vertices from chainage `from` to `to` (either direction), end points included.
    pub fn sub_line(&self, from: f64, to: f64) -> Vec<(f64, f64)> {
        let (Some(line), Some(_)) = (&self.line, self.cum.last()) else {
            return Vec::new();
        };
        let (lo, hi) = (from.min(to), from.max(to));
        let mut pts = Vec::new();
        pts.extend(self.point_at(lo));
        for (p, &c) in line.points.iter().zip(&self.cum) {
            if c > lo && c < hi {
                pts.push(*p);
            }
        }
        pts.extend(self.point_at(hi));
        if from > to {
            pts.reverse();
        }
        pts
    }

    /// Nearest point of the line to `p`: (distance, chainage).
    fn nearest(&self, p: (f64, f64)) -> Option<(f64, f64)> {
        let line = self.line.as_ref()?;
        let mut best: Option<(f64, f64)> = None;
        for (i, w) in line.points.windows(2).enumerate() {
            let (a, b) = (w[0], w[1]);
            let (dx, dy) = (b.0 - a.0, b.1 - a.1);
            let l2 = dx * dx + dy * dy;
            let t = if l2 > 0.0 {
                (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / l2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let q = (a.0 + t * dx, a.1 + t * dy);
            let d = (p.0 - q.0).hypot(p.1 - q.1);
            if best.is_none_or(|(bd, _)| d < bd) {
                best = Some((d, self.cum[i] + t * (self.cum[i + 1] - self.cum[i])));
            }
        }
        best
    }
}

fn cumulative(line: &LineString) -> Vec<f64> {
    let mut cum = Vec::with_capacity(line.points.len());
    let mut s = 0.0;
    cum.push(0.0);
    for w in line.points.windows(2) {
        s += (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1);
        cum.push(s);
    }
    cum
}

/// Where a sensor is, as the user gives it.
#[derive(Debug, Clone, PartialEq)]
pub enum SensorSpec {
    /// On a segment, `chainage` m along its geometry from the first vertex.
    OnSegment {
        /// Asset id.
        segment_id: String,
        /// Chainage, m.
        chainage_m: f64,
    },
    /// Map coordinates in the network's coordinate system, snapped to the nearest segment.
    Map {
        /// Easting (x).
        x: f64,
        /// Northing (y).
        y: f64,
    },
}

/// A sensor placed on a segment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorAt {
    /// Index of the segment in the network.
    pub segment: usize,
    /// Chainage, m from the segment's first vertex.
    pub chainage_m: f64,
}

/// A stretch of one segment on the path, from chainage `from_m` to `to_m` (in path order).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Piece {
    /// Index of the segment in the network.
    pub segment: usize,
    /// Chainage where the path enters the stretch, m.
    pub from_m: f64,
    /// Chainage where the path leaves it, m.
    pub to_m: f64,
}

impl Piece {
    /// Length of the stretch, m.
    pub fn length_m(&self) -> f64 {
        (self.to_m - self.from_m).abs()
    }
}

/// The path from sensor 1 to sensor 2: pieces of segments in order.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorPath {
    /// The stretches, from sensor 1.
    pub pieces: Vec<Piece>,
}

impl SensorPath {
    /// Span D, m: the length along the path.
    pub fn span_m(&self) -> f64 {
        self.pieces.iter().map(Piece::length_m).sum()
    }

    /// The piece holding path position `x` (m from sensor 1) and the chainage there.
    pub fn locate(&self, x: f64) -> (usize, f64) {
        let mut start = 0.0;
        for (i, p) in self.pieces.iter().enumerate() {
            let l = p.length_m();
            if x <= start + l || i + 1 == self.pieces.len() {
                let t = (x - start).clamp(0.0, l);
                let dir = if p.to_m >= p.from_m { 1.0 } else { -1.0 };
                return (i, p.from_m + dir * t);
            }
            start += l;
        }
        (0, 0.0)
    }
}

/// The segments of a network, their junction graph, and one coordinate system.
#[derive(Debug)]
pub struct Network {
    /// The segments.
    pub segments: Vec<NetSegment>,
    index: HashMap<String, usize>,
    /// EPSG code of the lines, when any segment has one.
    pub srid: Option<i64>,
    graph: UnGraph<(f64, f64), usize>,
    /// The (first, last) junction of each segment with a line.
    ends: Vec<Option<(NodeIndex, NodeIndex)>>,
}

impl Network {
    /// Build from the inventory: lines reprojected into the system most segments use, which must
    /// be projected (metres); end points within `join_tolerance_m` are one junction. A stored
    /// geometry that cannot be used (unreadable, in an unknown system, outside its system's
    /// coordinates, of zero length, or not reprojectable) makes only its segment unusable
    /// ([`NetSegment::unusable`]): the jobs that need it fail, the others are located.
    pub fn from_records(
        records: &[SegmentRecord],
        join_tolerance_m: f64,
    ) -> Result<Network, LocateError> {
        let lines: Vec<Option<Result<LineString, String>>> = records
            .iter()
            .map(|r| {
                r.geometry_wkt
                    .as_deref()
                    .map(|w| crs::usable_line(w, r.srid))
            })
            .collect();
        let srid = crs::dominant_srid(
            records
                .iter()
                .zip(&lines)
                .filter(|(_, l)| matches!(l, Some(Ok(_))))
                .filter_map(|(r, _)| r.srid),
        );
        if let Some(s) = srid.filter(|&s| crs::is_geographic(s)) {
            return Err(LocateError::Network(format!(
                "the network's geometries are in EPSG:{s}, a longitude/latitude system; locate \
                 measures chainage in metres and needs a projected system (re-import the \
                 segments in the utility's projected CRS)"
            )));
        }
        let mut to = srid.map(ToCommonCrs::new);
        let mut segments = Vec::with_capacity(records.len());
        for (r, line) in records.iter().zip(lines) {
            let id = r.segment_id.clone();
            let line = match (line, r.srid, to.as_mut()) {
                (Some(Err(why)), _, _) => Err(why),
                (Some(Ok(l)), Some(from), Some(to)) => {
                    to.line(from, &l).map(Some).map_err(|e| e.to_string())
                }
                (Some(Ok(l)), None, _) if srid.is_none() => Ok(Some(l)),
                _ => Ok(None),
            };
            segments.push(match line {
                Ok(line) => NetSegment::new(id, line, r.length_m),
                Err(why) => NetSegment::unusable(id, why),
            });
        }
        Ok(Network::from_segments(segments, srid, join_tolerance_m))
    }

    /// Build from segments already in one projected system.
    pub fn from_segments(
        segments: Vec<NetSegment>,
        srid: Option<i64>,
        join_tolerance_m: f64,
    ) -> Network {
        let tol = join_tolerance_m.max(1e-9);
        let mut graph = UnGraph::new_undirected();
        let mut cells: HashMap<(i64, i64), Vec<NodeIndex>> = HashMap::new();
        let mut node_at = |graph: &mut UnGraph<(f64, f64), usize>, p: (f64, f64)| {
            let cell = ((p.0 / tol).floor() as i64, (p.1 / tol).floor() as i64);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    if let Some(v) = cells.get(&(cell.0 + dx, cell.1 + dy)) {
                        for &n in v {
                            let q: (f64, f64) = graph[n];
                            if (q.0 - p.0).hypot(q.1 - p.1) <= tol {
                                return n;
                            }
                        }
                    }
                }
            }
            let n = graph.add_node(p);
            cells.entry(cell).or_default().push(n);
            n
        };
        let mut ends = Vec::with_capacity(segments.len());
        for (i, s) in segments.iter().enumerate() {
            ends.push(s.line.as_ref().map(|l| {
                let a = node_at(&mut graph, l.points[0]);
                let b = node_at(&mut graph, *l.points.last().expect("2 points"));
                graph.add_edge(a, b, i);
                (a, b)
            }));
        }
        let index = segments
            .iter()
            .enumerate()
            .map(|(i, s)| (s.id.clone(), i))
            .collect();
        Network {
            segments,
            index,
            srid,
            graph,
            ends,
        }
    }

    /// Index of a segment by id.
    pub fn segment(&self, id: &str) -> Result<usize, LocateError> {
        self.index
            .get(id)
            .copied()
            .ok_or_else(|| LocateError::Network(format!("segment {id} is not in the inventory")))
    }

    /// Place a sensor: a chainage checked against the segment's length, or map coordinates
    /// snapped to the nearest line within `snap_tolerance_m`.
    pub fn place(&self, s: &SensorSpec, snap_tolerance_m: f64) -> Result<SensorAt, LocateError> {
        match s {
            SensorSpec::OnSegment {
                segment_id,
                chainage_m,
            } => {
                let i = self.segment(segment_id)?;
                self.segments[i].usable()?;
                let Some(len) = self.segments[i].length_m else {
                    return Err(LocateError::Network(format!(
                        "segment {segment_id} has neither a geometry nor a length_m, so no \
                         chainage can be placed on it"
                    )));
                };
                if !chainage_m.is_finite()
                    || *chainage_m < -CHAINAGE_SLACK_M
                    || *chainage_m > len + CHAINAGE_SLACK_M
                {
                    return Err(LocateError::Network(format!(
                        "chainage {chainage_m} m is off segment {segment_id}, which is {:.2} m \
                         long (chainage runs from 0 at its first vertex)",
                        len
                    )));
                }
                Ok(SensorAt {
                    segment: i,
                    chainage_m: chainage_m.clamp(0.0, len),
                })
            }
            SensorSpec::Map { x, y } => {
                let best = self
                    .segments
                    .iter()
                    .enumerate()
                    .filter_map(|(i, s)| s.nearest((*x, *y)).map(|(d, c)| (d, i, c)))
                    .min_by(|a, b| a.0.total_cmp(&b.0));
                match best {
                    Some((d, i, c)) if d <= snap_tolerance_m => Ok(SensorAt {
                        segment: i,
                        chainage_m: c,
                    }),
                    Some((d, i, _)) => Err(LocateError::Network(format!(
                        "the sensor at ({x}, {y}) is off the network: the nearest segment, {}, \
                         is {d:.1} m away, beyond the snap tolerance of {snap_tolerance_m} m",
                        self.segments[i].id
                    ))),
                    None => Err(LocateError::Network(
                        "no segment has a geometry, so map coordinates cannot be placed; give \
                         segment and chainage"
                            .into(),
                    )),
                }
            }
        }
    }

    /// The shortest path along the geometry from sensor 1 to sensor 2.
    pub fn route(&self, s1: SensorAt, s2: SensorAt) -> Result<SensorPath, LocateError> {
        if s1.segment == s2.segment {
            return Ok(SensorPath {
                pieces: vec![Piece {
                    segment: s1.segment,
                    from_m: s1.chainage_m,
                    to_m: s2.chainage_m,
                }],
            });
        }
        let ends_of = |s: SensorAt| -> Result<[(NodeIndex, f64, f64); 2], LocateError> {
            let seg = &self.segments[s.segment];
            let (Some((a, b)), Some(len)) = (self.ends[s.segment], seg.length_m) else {
                return Err(LocateError::Network(format!(
                    "segment {} has no geometry, so no path can be routed from it; give the \
                     path with --path (its length_m is then used)",
                    seg.id
                )));
            };
            // (junction, length from the sensor to it, chainage of that end)
            Ok([(a, s.chainage_m, 0.0), (b, len - s.chainage_m, len)])
        };
        let (e1, e2) = (ends_of(s1)?, ends_of(s2)?);
        let mut best: Option<(f64, usize, usize, Vec<NodeIndex>)> = None;
        for (i, &(n1, c1, _)) in e1.iter().enumerate() {
            for (j, &(n2, c2, _)) in e2.iter().enumerate() {
                let found = petgraph::algo::astar(
                    &self.graph,
                    n1,
                    |n| n == n2,
                    |e| self.segments[*e.weight()].length_m.unwrap_or(f64::INFINITY),
                    |_| 0.0,
                );
                if let Some((d, nodes)) = found {
                    let total = c1 + d + c2;
                    if best.as_ref().is_none_or(|b| total < b.0) {
                        best = Some((total, i, j, nodes));
                    }
                }
            }
        }
        let Some((_, i, j, nodes)) = best else {
            // Segments whose geometry cannot be used are not in the graph: one of them may be
            // the missing link.
            let unusable: Vec<&str> = self
                .segments
                .iter()
                .filter(|s| s.problem.is_some())
                .map(|s| s.id.as_str())
                .collect();
            let gap = match unusable.as_slice() {
                [] => String::new(),
                few if few.len() <= 5 => format!(
                    "; segments whose stored geometry cannot be used are left out of the \
                     network: {}",
                    few.join(", ")
                ),
                many => format!(
                    "; {} segments whose stored geometry cannot be used are left out of the \
                     network, among them {}",
                    many.len(),
                    many[..5].join(", ")
                ),
            };
            return Err(LocateError::Network(format!(
                "segments {} and {} are not connected through the network (no chain of \
                 segments whose end points meet within the join tolerance); give the path with \
                 --path{gap}",
                self.segments[s1.segment].id, self.segments[s2.segment].id
            )));
        };
        let mut pieces = vec![Piece {
            segment: s1.segment,
            from_m: s1.chainage_m,
            to_m: e1[i].2,
        }];
        for w in nodes.windows(2) {
            let e = self
                .graph
                .edges_connecting(w[0], w[1])
                .min_by(|a, b| {
                    let l = |e: &petgraph::graph::EdgeReference<'_, usize>| {
                        self.segments[*e.weight()].length_m.unwrap_or(f64::INFINITY)
                    };
                    l(a).total_cmp(&l(b))
                })
                .expect("consecutive nodes of a path are joined");
            let k = *e.weight();
            let len = self.segments[k].length_m.unwrap_or(0.0);
            let forward = self.ends[k].is_some_and(|(a, _)| a == w[0]);
            pieces.push(Piece {
                segment: k,
                from_m: if forward { 0.0 } else { len },
                to_m: if forward { len } else { 0.0 },
            });
        }
        pieces.push(Piece {
            segment: s2.segment,
            from_m: e2[j].2,
            to_m: s2.chainage_m,
        });
        Ok(SensorPath { pieces })
    }

    /// An explicit path: the ids in order from sensor 1's segment to sensor 2's, consecutive
    /// segments with lines sharing a junction. A segment without a line is taken whole, with its
    /// `length_m`.
    pub fn explicit_path(
        &self,
        ids: &[String],
        s1: SensorAt,
        s2: SensorAt,
    ) -> Result<SensorPath, LocateError> {
        let idx: Vec<usize> = ids
            .iter()
            .map(|id| self.segment(id))
            .collect::<Result<_, _>>()?;
        for &i in &idx {
            self.segments[i].usable()?;
        }
        let err = |m: String| Err(LocateError::Path(m));
        let (Some(&first), Some(&last)) = (idx.first(), idx.last()) else {
            return err("the path is empty".into());
        };
        let name = |i: usize| self.segments[i].id.as_str();
        if first != s1.segment || last != s2.segment {
            return err(format!(
                "the path must run from sensor 1's segment {} to sensor 2's segment {}, but it \
                 runs from {} to {}",
                name(s1.segment),
                name(s2.segment),
                name(first),
                name(last)
            ));
        }
        if idx.len() == 1 {
            return self.route(s1, s2);
        }
        for &i in &idx {
            if self.segments[i].length_m.is_none() {
                return err(format!(
                    "segment {} on the path has neither a geometry nor a length_m",
                    name(i)
                ));
            }
        }
        // A leak's path between two sensors runs through each segment once: a path that comes
        // back to a segment (A, B, A, B) would count its length again, and the span with it.
        for (k, &i) in idx.iter().enumerate() {
            if let Some(j) = idx[..k].iter().position(|&e| e == i) {
                return err(format!(
                    "segment {} is on the path twice (places {} and {}): a path between two \
                     sensors goes through each segment once",
                    name(i),
                    j + 1,
                    k + 1
                ));
            }
        }
        // Contiguity of consecutive segments that both have lines; a segment without a line
        // cannot be checked and is trusted.
        for w in idx.windows(2) {
            if let (Some(a), Some(b)) = (self.ends[w[0]], self.ends[w[1]]) {
                if ![a.0, a.1].iter().any(|n| *n == b.0 || *n == b.1) {
                    let gap = [a.0, a.1]
                        .iter()
                        .flat_map(|&n| [b.0, b.1].map(|m| (n, m)))
                        .map(|(n, m)| {
                            let (p, q) = (self.graph[n], self.graph[m]);
                            (p.0 - q.0).hypot(p.1 - q.1)
                        })
                        .fold(f64::INFINITY, f64::min);
                    return err(format!(
                        "the path is not contiguous: segments {} and {} do not meet (their \
                         nearest end points are {gap:.1} m apart, beyond the join tolerance)",
                        name(w[0]),
                        name(w[1])
                    ));
                }
            }
        }
        // The end of segment `at` that faces the neighbour `toward` (the nearest segment with a
        // line in that direction along the path).
        let facing_end = |pos: usize, step: isize| -> Result<bool, LocateError> {
            let i = idx[pos];
            let Some((a, b)) = self.ends[i] else {
                return Err(LocateError::Path(format!(
                    "sensor segment {} has no geometry, so its chainage has no direction",
                    name(i)
                )));
            };
            let mut p = pos as isize + step;
            while p >= 0 && (p as usize) < idx.len() {
                if let Some((c, d)) = self.ends[idx[p as usize]] {
                    let dist = |n: NodeIndex| {
                        [c, d]
                            .iter()
                            .map(|&m| {
                                let (u, v) = (self.graph[n], self.graph[m]);
                                (u.0 - v.0).hypot(u.1 - v.1)
                            })
                            .fold(f64::INFINITY, f64::min)
                    };
                    // true: the last vertex faces the neighbour.
                    return Ok(dist(b) < dist(a));
                }
                p += step;
            }
            Err(LocateError::Path(format!(
                "no other segment on the path has a geometry, so the direction of segment {} \
                 cannot be known",
                name(i)
            )))
        };
        let len = |i: usize| self.segments[i].length_m.unwrap_or(0.0);
        let mut pieces = Vec::with_capacity(idx.len());
        let out_end = if facing_end(0, 1)? { len(first) } else { 0.0 };
        pieces.push(Piece {
            segment: first,
            from_m: s1.chainage_m,
            to_m: out_end,
        });
        let mut prev_exit = self.ends[first].map(|(a, b)| if out_end > 0.0 { b } else { a });
        for (pos, &i) in idx.iter().enumerate().skip(1).take(idx.len() - 2) {
            let forward = match (self.ends[i], prev_exit) {
                (Some((a, _)), Some(n)) => a == n,
                (Some(_), None) => !facing_end(pos, -1)?,
                (None, _) => true,
            };
            pieces.push(Piece {
                segment: i,
                from_m: if forward { 0.0 } else { len(i) },
                to_m: if forward { len(i) } else { 0.0 },
            });
            prev_exit = self.ends[i].map(|(a, b)| if forward { b } else { a });
        }
        let in_end = if facing_end(idx.len() - 1, -1)? {
            len(last)
        } else {
            0.0
        };
        pieces.push(Piece {
            segment: last,
            from_m: in_end,
            to_m: s2.chainage_m,
        });
        Ok(SensorPath { pieces })
    }

    /// A random walk of up to `steps` further segments from segment `start`, each joined to the
    /// previous at a junction and none repeated (for synthetic leak paths).
    pub fn walk<R: rand::Rng + ?Sized>(
        &self,
        start: usize,
        steps: usize,
        rng: &mut R,
    ) -> Vec<usize> {
        let mut out = vec![start];
        let Some((a, b)) = self.ends[start] else {
            return out;
        };
        let mut at = if rng.gen::<bool>() { a } else { b };
        for _ in 0..steps {
            let next: Vec<(usize, NodeIndex)> = self
                .graph
                .edges(at)
                .map(|e| {
                    (
                        *e.weight(),
                        if e.source() == at {
                            e.target()
                        } else {
                            e.source()
                        },
                    )
                })
                .filter(|(k, _)| !out.contains(k))
                .collect();
            if next.is_empty() {
                break;
            }
            let (k, far) = next[rng.gen_range(0..next.len())];
            out.push(k);
            at = far;
        }
        out
    }

    /// The map point at path position `x` (m from sensor 1), if that piece has a line.
    pub fn point_on_path(&self, path: &SensorPath, x: f64) -> Option<(f64, f64)> {
        let (i, c) = path.locate(x);
        self.segments[path.pieces[i].segment].point_at(c)
    }

    /// The line along the path from position `lo` to `hi` (m from sensor 1), through the pieces
    /// that have lines.
    pub fn line_on_path(&self, path: &SensorPath, lo: f64, hi: f64) -> Vec<(f64, f64)> {
        let mut out: Vec<(f64, f64)> = Vec::new();
        let mut start = 0.0;
        for p in &path.pieces {
            let l = p.length_m();
            let (a, b) = (lo.max(start), hi.min(start + l));
            if b >= a {
                let dir = if p.to_m >= p.from_m { 1.0 } else { -1.0 };
                let seg = &self.segments[p.segment];
                for q in seg.sub_line(p.from_m + dir * (a - start), p.from_m + dir * (b - start)) {
                    if out.last() != Some(&q) {
                        out.push(q);
                    }
                }
            }
            start += l;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg(id: &str, pts: &[(f64, f64)]) -> NetSegment {
        NetSegment::new(
            id.into(),
            Some(LineString {
                points: pts.to_vec(),
            }),
            None,
        )
    }

    /// A street of three segments, the middle one drawn backwards, and a branch.
    fn street() -> Network {
        Network::from_segments(
            vec![
                seg("A", &[(0.0, 0.0), (100.0, 0.0)]),
                seg("B", &[(150.0, 0.0), (100.3, 0.0)]),
                seg("C", &[(150.0, 0.0), (150.0, 80.0)]),
                seg("X", &[(100.0, 0.0), (100.0, 50.0)]),
                NetSegment::new("N".into(), None, Some(30.0)),
            ],
            Some(27700),
            1.0,
        )
    }

    #[test]
    fn routes_along_the_geometry_through_reversed_segments() {
        let n = street();
        let s1 = SensorAt {
            segment: 0,
            chainage_m: 20.0,
        };
        let s2 = SensorAt {
            segment: 2,
            chainage_m: 30.0,
        };
        let p = n.route(s1, s2).unwrap();
        let segs: Vec<usize> = p.pieces.iter().map(|p| p.segment).collect();
        assert_eq!(segs, vec![0, 1, 2]);
        assert!((p.span_m() - (80.0 + 49.7 + 30.0)).abs() < 1e-9);
        assert_eq!((p.pieces[1].from_m, p.pieces[1].to_m), (49.7, 0.0));
        // Position 100 m from sensor 1 is 20 m into B, counted back from its chainage 49.7.
        let (i, c) = p.locate(100.0);
        assert_eq!(i, 1);
        assert!((c - 29.7).abs() < 1e-9);
        let q = n.point_on_path(&p, 100.0).unwrap();
        assert!((q.0 - 120.3).abs() < 1e-9 && q.1.abs() < 1e-9, "{q:?}");
        let line = n.line_on_path(&p, 70.0, 140.0);
        assert!((line[0].0 - 90.0).abs() < 1e-9);
        assert!((line.last().unwrap().1 - 10.3).abs() < 1e-9);
    }

    #[test]
    fn explicit_path_is_checked_for_contiguity() {
        let n = street();
        let s1 = SensorAt {
            segment: 0,
            chainage_m: 20.0,
        };
        let s2 = SensorAt {
            segment: 2,
            chainage_m: 30.0,
        };
        let ids = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let p = n.explicit_path(&ids(&["A", "B", "C"]), s1, s2).unwrap();
        assert_eq!(p, n.route(s1, s2).unwrap());
        let e = n.explicit_path(&ids(&["A", "C"]), s1, s2).unwrap_err();
        assert!(e.to_string().contains("not contiguous"), "{e}");
        assert!(e.to_string().contains("A and C"), "{e}");
        // A segment without geometry is taken whole, with its length_m.
        let p = n.explicit_path(&ids(&["A", "N", "C"]), s1, s2).unwrap();
        assert!((p.span_m() - (80.0 + 30.0 + 30.0)).abs() < 1e-9);
        let e = n.explicit_path(&ids(&["B", "C"]), s1, s2).unwrap_err();
        assert!(e.to_string().contains("sensor 1's segment A"), "{e}");
        // Back and forth would count B's length twice.
        let e = n
            .explicit_path(&ids(&["A", "B", "A", "B", "C"]), s1, s2)
            .unwrap_err();
        assert!(
            e.to_string()
                .contains("segment A is on the path twice (places 1 and 3)"),
            "{e}"
        );
    }

    #[test]
    fn a_stored_geometry_that_cannot_be_used_costs_only_its_segment() {
        let rec = |id: &str, wkt: &str, srid: i64| SegmentRecord {
            segment_id: id.into(),
            geometry_wkt: Some(wkt.into()),
            srid: Some(srid),
            ..SegmentRecord::new(
                id,
                crate::physics::Material::DuctileIron,
                170.0,
                6.0,
                1900.0,
            )
        };
        let records = vec![
            rec("A", "LINESTRING (441800 111900, 441920 111900)", 27700),
            rec("B", "LINESTRING (441920 111900, 442040 111900)", 999_999),
            rec("C", "LINESTRING (442040 111900, 442040 111900)", 27700),
            rec("D", "LINESTRING (442040 111900, 442160 111900)", 27700),
        ];
        let n = Network::from_records(&records, 1.0).unwrap();
        assert_eq!(n.srid, Some(27700));
        let on = |id: &str| SensorSpec::OnSegment {
            segment_id: id.into(),
            chainage_m: 10.0,
        };
        assert!(n.place(&on("A"), 5.0).is_ok());
        for (id, why) in [("B", "EPSG:999999"), ("C", "zero length")] {
            let e = n.place(&on(id), 5.0).unwrap_err().to_string();
            assert!(
                e.contains(&format!("segment {id}:")) && e.contains(why),
                "{e}"
            );
        }
        let (a, d) = (
            n.place(&on("A"), 5.0).unwrap(),
            n.place(&on("D"), 5.0).unwrap(),
        );
        let e = n.route(a, d).unwrap_err().to_string();
        assert!(e.contains("left out of the network: B, C"), "{e}");
        let ids: Vec<String> = ["A", "B", "D"].iter().map(|s| s.to_string()).collect();
        let e = n.explicit_path(&ids, a, d).unwrap_err().to_string();
        assert!(e.contains("segment B:"), "{e}");
    }

    #[test]
    fn sensors_snap_within_the_tolerance_only() {
        let n = street();
        let s = n.place(&SensorSpec::Map { x: 40.0, y: 3.0 }, 5.0).unwrap();
        assert_eq!(s.segment, 0);
        assert!((s.chainage_m - 40.0).abs() < 1e-9);
        let e = n
            .place(&SensorSpec::Map { x: 40.0, y: 30.0 }, 5.0)
            .unwrap_err();
        assert!(e.to_string().contains("off the network"), "{e}");
        assert!(e.to_string().contains("30.0 m away"), "{e}");
        let e = n
            .place(
                &SensorSpec::OnSegment {
                    segment_id: "A".into(),
                    chainage_m: 130.0,
                },
                5.0,
            )
            .unwrap_err();
        assert!(e.to_string().contains("off segment A"), "{e}");
        let e = n
            .place(
                &SensorSpec::OnSegment {
                    segment_id: "Q".into(),
                    chainage_m: 1.0,
                },
                5.0,
            )
            .unwrap_err();
        assert!(e.to_string().contains("Q is not in the inventory"), "{e}");
    }
}
