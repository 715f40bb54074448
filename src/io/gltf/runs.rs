//! Accessors that name the same elements: shared geometry is one set of vertices.
//!
//! An element is its bytes: two accessors name the same element when it starts at the same byte of
//! the same buffer. Spans of one buffer and one stride whose offsets differ by whole strides line
//! up; their union, merged where they overlap (touching is not overlapping), is a run. Each
//! element of a run is one vertex (or one normal) however many accessors name it. Any other
//! overlap of rewritten bytes (other strides, out of step) is refused by the reader.

use std::collections::BTreeMap;

use super::Span;

/// Elements `first..end` of a run: element `k` starts at byte `phase + k * stride` of `buffer`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Run {
    pub(super) buffer: usize,
    pub(super) stride: usize,
    pub(super) phase: usize,
    pub(super) first: usize,
    pub(super) end: usize,
    /// The accessor of its first span, to name it in messages.
    pub(super) accessor: usize,
}

impl Run {
    /// Where element `k` (of `first..end`) starts.
    pub(super) fn byte(&self, k: usize) -> usize {
        self.phase + k * self.stride
    }

    pub(super) fn len(&self) -> usize {
        self.end - self.first
    }
}

/// The runs of `spans` in the order their first span comes, and for each span its run and the
/// place of its element 0 in that run (`None` for an empty span). Spans of different `tag`s never
/// share a run: a tag says what an element means beyond its bytes (the vertex a normal is of).
pub(super) fn runs(spans: &[(Span, i64)]) -> (Vec<Run>, Vec<Option<(usize, usize)>>) {
    type Key = (usize, usize, usize, i64);
    let mut groups: BTreeMap<Key, Vec<(usize, usize, usize)>> = BTreeMap::new();
    for (i, &(s, tag)) in spans.iter().enumerate() {
        if s.count > 0 {
            let first = s.offset / s.stride;
            let key = (s.buffer, s.stride, s.offset % s.stride, tag);
            groups
                .entry(key)
                .or_default()
                .push((first, first + s.count, i));
        }
    }
    // Each run with the first of its spans (which orders the runs) and all of them.
    let mut merged: Vec<(usize, Run, Vec<usize>)> = Vec::new();
    for ((buffer, stride, phase, _), mut members) in groups {
        members.sort_unstable();
        let mut open: Option<(usize, Run, Vec<usize>)> = None;
        for (first, end, i) in members {
            match &mut open {
                Some((order, run, of)) if first < run.end => {
                    run.end = run.end.max(end);
                    if i < *order {
                        *order = i;
                        run.accessor = spans[i].0.accessor;
                    }
                    of.push(i);
                }
                _ => {
                    let run = Run {
                        buffer,
                        stride,
                        phase,
                        first,
                        end,
                        accessor: spans[i].0.accessor,
                    };
                    merged.extend(open.replace((i, run, vec![i])));
                }
            }
        }
        merged.extend(open);
    }
    merged.sort_unstable_by_key(|(order, _, _)| *order);
    let mut place = vec![None; spans.len()];
    for (r, (_, run, of)) in merged.iter().enumerate() {
        for &i in of {
            let s = spans[i].0;
            place[i] = Some((r, s.offset / s.stride - run.first));
        }
    }
    (merged.into_iter().map(|(_, run, _)| run).collect(), place)
}
