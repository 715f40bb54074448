//! The work directory of a cluster run: the prepared plan (reordered mesh, adjacency, patches,
//! colours) as raw arrays that every rank maps, and the checkpoint (positions after the last
//! completed iteration).
//!
//! Files (all written by rank 0, except the positions, whose owned ranges each rank writes):
//! - `plan.json`: what the arrays hold and what they were made from (the SHA-256 of the input
//!   and of the files it names, method options, patch size, pins). Written last: a directory without it holds no usable plan.
//! - `order.u32` (reordered → input vertex), `triangles.u32` (reordered, smallest vertex first),
//!   `vv_offsets.u64`, `vv.u32`, `fixed.u8` (the adjacency) and `face_runs.u32` (where each
//!   vertex's run of triangles starts: [`crate::topology::FaceIndex::Runs`]) for a plan made out
//!   of core, or `vf_offsets.u64`, `vf.u32` (the faces listed) for one made in memory;
//!   `welded.u32` (reordered → the vertex whose position it takes), only when some are welded;
//!   `lines.u8` (the crease line vertices' crease neighbours), only with creases.
//! - `positions-0.f64`, `positions-1.f64`: two slots of `3 × f64` per reordered vertex. An
//!   iteration's positions go to the slot that `state.json` does not name; only when every rank
//!   has written and synced its part does rank 0 switch `state.json` (atomic rename) to it. A run
//!   killed at any moment therefore finds a complete slot for the iteration `state.json` names.
//! - `input.f64`: the reordered input positions, only for a deviation bound (`max_deviation`).
//!
//! The directory must be on a file system every rank sees (for one machine, any directory).

use std::fs::{self, File, OpenOptions};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use glam::DVec3;

use crate::engine::observer::metered;
use crate::engine::{self, IterationRecord, Observer, Phase};
use crate::error::{Error, Result};
use crate::io;
use crate::mesh::Buf;
use crate::mesh::storage::{Pod, as_bytes};
use crate::metrics::MeshInfo;
use crate::partition::Patch;
use crate::topology::{FaceIndex, FaceParts, Topology, TopologyStats};

/// 2: vertices welded; 3: faces found in runs (a plan of an earlier format is made again).
const FORMAT: u32 = 3;
const PLAN: &str = "plan.json";
const STATE: &str = "state.json";
const INPUT: &str = "input.f64";
const LOOPS: &str = "loops.u32";
const WELDED: &str = "welded.u32";
const LINES: &str = "lines.u8";
const RUNS: &str = "face_runs.u32";

/// Every file a run writes in its work directory (and removes from it after a run without
/// `--checkpoint`): no other file of the run may be one of them.
pub const FILES: [&str; 16] = [
    PLAN,
    STATE,
    "order.u32",
    "triangles.u32",
    "vv_offsets.u64",
    "vv.u32",
    "vf_offsets.u64",
    "vf.u32",
    "fixed.u8",
    "positions-0.f64",
    "positions-1.f64",
    INPUT,
    LOOPS,
    WELDED,
    LINES,
    RUNS,
];

/// What a plan was made from; a plan is reused only when all of it matches.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlanKey {
    pub format: u32,
    /// The SHA-256 of the input's bytes, then of each file it names (a glTF's buffers and
    /// images), in that order: what the run reads, whatever its name, folder or time. Empty in
    /// plans made before it, which are therefore made again.
    #[serde(default)]
    pub input_sha256: Vec<String>,
    pub input_size: u64,
    /// The options that change results (method, λ, μ, rejection), as JSON.
    pub options: String,
    pub patch_size: usize,
    /// The pinned vertices ([`crate::engine::Pins::key`]); empty for none.
    #[serde(default)]
    pub pins: String,
}

impl PlanKey {
    /// The key of `input` smoothed with `options` (iterations excluded: a resumed run may go on
    /// further) at `patch_size` with `pins`. Hashing the input is a [`Phase::Hash`] of
    /// `observer`'s.
    pub fn of(
        input: &Path,
        opts: &crate::Options,
        patch_size: usize,
        pins: &crate::engine::Pins,
        observer: &mut dyn Observer,
    ) -> Result<PlanKey> {
        let meta = fs::metadata(input).map_err(|e| Error::io(input, e))?;
        let mut options = serde_json::json!({
            // A plan or checkpoint of another results version is another run's (its order of
            // work and arithmetic may differ).
            "results_version": crate::RESULTS_VERSION,
            "method": opts.method,
            "lambda": opts.lambda,
            "mu": opts.mu(),
            "reject_energy_increase": opts.reject_energy_increase,
        });
        // Creases are fixed in the stored topology, the deviation bound needs the stored input
        // positions; keys without them are as they were.
        if let Some(a) = opts.crease_angle {
            options["crease_angle"] = a.into();
            // Crease line vertices move along their creases (results version 8): a plan made
            // before, whose topology fixes them, is made again.
            options["crease_lines"] = true.into();
        }
        if let Some(d) = opts.max_deviation {
            options["max_deviation"] = d.into();
        }
        // The automatic stop needs the stored input positions, smoothed boundaries the stored
        // loops, and a checkpoint of either is another run's.
        if opts.auto_stop {
            options["auto_stop"] = true.into();
        }
        if !opts.boundary.is_fixed() {
            options["boundary"] = opts.boundary.name().into();
        }
        if !opts.weld {
            options["weld"] = false.into();
        }
        if opts.weld_tolerance > 0.0 {
            options["weld_tolerance"] = opts.weld_tolerance.into();
        }
        let mut files = vec![input.to_path_buf()];
        files.extend(
            io::referenced_files(input)
                .into_iter()
                .filter(|f| f.is_file()),
        );
        let bytes = files
            .iter()
            .map(|f| fs::metadata(f).map_or(0, |m| m.len()))
            .sum();
        let input_sha256 = metered(observer, Phase::Hash, bytes, |meter| {
            files
                .iter()
                .map(|f| io::sha256_counted(f, meter))
                .collect::<Result<Vec<_>>>()
        })?;
        Ok(PlanKey {
            format: FORMAT,
            input_sha256,
            input_size: meta.len(),
            options: options.to_string(),
            patch_size,
            pins: pins.key()?,
        })
    }
}

/// `plan.json`.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct PlanDoc {
    pub key: PlanKey,
    pub vertices: usize,
    pub triangles: usize,
    /// Per patch: owned vertices `[lo, hi)` and owned triangles `[lo, hi)`.
    pub patches: Vec<[u32; 4]>,
    pub colours: Vec<Vec<u32>>,
    pub halo: Vec<u32>,
    /// `vcs-guided`'s colouring (see [`crate::schedule::Schedule::ring_colours`]); empty in
    /// plans made before it.
    #[serde(default)]
    pub ring_colours: Vec<Vec<u32>>,
    #[serde(default)]
    pub ring_halo: Vec<u32>,
    /// Directed boundary edges stored in `loops.u32` (`boundary: smooth`; 0 otherwise).
    #[serde(default)]
    pub boundary_edges: usize,
    /// Welded copies ([`crate::partition::Reordered::welded`]); `welded.u32` is stored when not 0.
    #[serde(default)]
    pub welded: usize,
    /// Whether the crease line array is stored in `lines.u8` (with creases).
    #[serde(default)]
    pub crease_lines: bool,
    /// Whether the faces are found in runs (`face_runs.u32`) rather than listed.
    #[serde(default)]
    pub face_runs: bool,
    pub crossing_edge_stencils: u64,
    pub topology: TopologyStats,
    /// Input statistics, when the run that made the plan measured them.
    pub input_stats: Option<MeshInfo>,
}

impl PlanDoc {
    pub fn patch(&self, p: usize) -> Patch {
        let [a, b, c, d] = self.patches[p];
        Patch {
            vertices: a..b,
            triangles: c..d,
        }
    }
}

/// Reference values of the input, fixed when the run first starts, so that a resumed run reports
/// percentages relative to the input as an uninterrupted one does.
pub use crate::engine::Reference;

/// `state.json`: iterations completed, which positions slot holds them, and their records.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct StateDoc {
    pub done: usize,
    pub slot: u8,
    pub reference: Option<Reference>,
    pub records: Vec<IterationRecord>,
    /// The automatic stop's `O_k` of the iterations done, and why it ended the run if it has
    /// (see [`crate::engine::auto::AutoStop::resume`]); empty and `None` without it.
    #[serde(default)]
    pub auto_removed: Vec<f64>,
    #[serde(default)]
    pub auto_stopped: Option<engine::StopReason>,
}

/// A plan mapped from the work directory.
pub struct StoredPlan {
    /// The work directory it was mapped from (for messages).
    pub dir: PathBuf,
    pub doc: PlanDoc,
    pub topology: Topology,
    pub triangles: Buf<[u32; 3]>,
    pub order: Buf<u32>,
    /// [`crate::partition::Reordered::welded_to`]: empty when no vertex is welded.
    pub welded_to: Buf<u32>,
}

/// Paths in the work directory.
pub struct WorkDir {
    pub dir: PathBuf,
}

impl WorkDir {
    pub fn new(dir: &Path) -> WorkDir {
        WorkDir {
            dir: dir.to_path_buf(),
        }
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    pub fn positions(&self, slot: u8) -> PathBuf {
        self.path(&format!("positions-{slot}.f64"))
    }

    /// The plan's description, if a complete plan is there.
    pub fn read_plan_doc(&self) -> Result<Option<PlanDoc>> {
        read_json(&self.path(PLAN))
    }

    /// The checkpoint state (a complete plan always has one).
    pub fn read_state(&self) -> Result<StateDoc> {
        let path = self.path(STATE);
        read_json(&path)?.ok_or_else(|| Error::invalid(&path, "missing; the plan is incomplete"))
    }

    /// Write the checkpoint state atomically.
    pub fn write_state(&self, state: &StateDoc) -> Result<()> {
        write_json(&self.path(STATE), state)
    }

    /// Store `made` (fresh from [`engine::Plan::new`]) as the plan, replacing whatever plan was
    /// there; with `keep_input`, also its positions as `input.f64` (read by a deviation bound, by
    /// a resumed automatic stop and by resumed smooth boundaries); `loops`: the directed boundary
    /// edges of `boundary: smooth`.
    pub fn write_plan(
        &self,
        made: &engine::Plan,
        key: PlanKey,
        input_stats: Option<MeshInfo>,
        keep_input: bool,
        loops: &[[u32; 2]],
    ) -> Result<()> {
        fs::create_dir_all(&self.dir).map_err(|e| Error::io(&self.dir, e))?;
        // The plan's marker goes first and comes back last: a half-written plan is never used.
        for stale in [PLAN, STATE] {
            match fs::remove_file(self.path(stale)) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(Error::io(self.path(stale), e));
                }
                _ => {}
            }
        }
        let parts = made.topology.parts();
        self.write_array("order.u32", &made.reordered.order)?;
        self.write_array("triangles.u32", &made.reordered.triangles)?;
        self.write_array("vv_offsets.u64", parts.vv_offsets)?;
        self.write_array("vv.u32", parts.vv)?;
        match parts.faces {
            FaceParts::Lists { offsets, faces } => {
                self.write_array("vf_offsets.u64", offsets)?;
                self.write_array("vf.u32", faces)?;
            }
            FaceParts::Runs { starts } => self.write_array(RUNS, starts)?,
        }
        self.write_array("fixed.u8", parts.fixed)?;
        if !parts.lines.is_empty() {
            self.write_array(LINES, parts.lines)?;
        }
        for slot in [0, 1] {
            let name = format!("positions-{slot}.f64");
            self.write_array(&name, &made.reordered.positions)?;
        }
        if keep_input {
            self.write_array(INPUT, &made.reordered.positions)?;
        }
        if !loops.is_empty() {
            self.write_array(LOOPS, loops)?;
        }
        if made.reordered.welded > 0 {
            self.write_array(WELDED, &made.reordered.welded_to)?;
        }
        self.write_state(&StateDoc::default())?;
        // The crossing edge stencils do not depend on the method.
        let stats = made.stats(crate::smooth::method::Footprint::Edge);
        let doc = PlanDoc {
            key,
            vertices: made.reordered.positions.len(),
            triangles: made.reordered.triangles.len(),
            patches: made
                .patches
                .iter()
                .map(|p| {
                    [
                        p.vertices.start,
                        p.vertices.end,
                        p.triangles.start,
                        p.triangles.end,
                    ]
                })
                .collect(),
            colours: made.schedule.colours.clone(),
            halo: made.schedule.halo.clone(),
            ring_colours: made.schedule.ring_colours.clone(),
            ring_halo: made.schedule.ring_halo.clone(),
            boundary_edges: loops.len(),
            welded: made.reordered.welded,
            crease_lines: !parts.lines.is_empty(),
            face_runs: matches!(parts.faces, FaceParts::Runs { .. }),
            crossing_edge_stencils: stats.crossing_edge_stencils,
            topology: made.topology.stats,
            input_stats,
        };
        write_json(&self.path(PLAN), &doc)
    }

    fn write_array<T: Pod>(&self, name: &str, data: &[T]) -> Result<()> {
        let path = self.path(name);
        let write = || -> std::io::Result<()> {
            let mut f = File::create(&path)?;
            std::io::Write::write_all(&mut f, as_bytes(data))?;
            f.sync_all()
        };
        write().map_err(|e| Error::io(&path, e))
    }

    /// Map the plan (each rank; only the pages a rank uses are ever read).
    pub fn open_plan(&self) -> Result<StoredPlan> {
        let plan_path = self.path(PLAN);
        let doc = self
            .read_plan_doc()?
            .ok_or_else(|| Error::invalid(&plan_path, "missing"))?;
        let (n, t) = (doc.vertices, doc.triangles);
        // The adjacency is checked against the topology's counts, the triangles mapped by the
        // plan's: they must agree.
        if doc.topology.triangles != t || doc.topology.vertices != n {
            return Err(Error::invalid(
                &plan_path,
                "its topology counts another mesh than its arrays hold",
            ));
        }
        let m = |name: &str| self.path(name);
        let topology = Topology::from_parts(
            Buf::map_file(&m("vv_offsets.u64"), n + 1)?,
            Buf::map_file(&m("vv.u32"), doc.topology.edges * 2)?,
            match doc.face_runs {
                true => FaceIndex::Runs {
                    starts: Buf::map_file(&m(RUNS), n + 1)?,
                },
                false => FaceIndex::Lists {
                    offsets: Buf::map_file(&m("vf_offsets.u64"), n + 1)?,
                    faces: Buf::map_file(
                        &m("vf.u32"),
                        3 * (t - doc.topology.degenerate_triangles),
                    )?,
                },
            },
            Buf::map_file(&m("fixed.u8"), n)?,
            match doc.crease_lines {
                true => Buf::map_file(&m(LINES), 2 * n)?,
                false => Buf::default(),
            },
            doc.topology,
        )
        .map_err(|e| Error::invalid(&self.dir, e))?;
        let patches_ok = doc
            .patches
            .iter()
            .all(|p| p[0] <= p[1] && p[1] as usize <= n && p[2] <= p[3] && p[3] as usize <= t)
            && doc
                .colours
                .iter()
                .chain(&doc.ring_colours)
                .flatten()
                .all(|&p| (p as usize) < doc.patches.len());
        if !patches_ok {
            return Err(Error::invalid(&plan_path, "patches out of range"));
        }
        let welded_to = match doc.welded {
            0 => Buf::default(),
            _ => {
                let to: Buf<u32> = Buf::map_file(&m(WELDED), n)?;
                if to.iter().any(|&v| v as usize >= n) {
                    return Err(Error::invalid(m(WELDED), "names a vertex out of range"));
                }
                to
            }
        };
        Ok(StoredPlan {
            welded_to,
            triangles: Buf::map_file(&m("triangles.u32"), t)?,
            order: Buf::map_file(&m("order.u32"), n)?,
            topology,
            doc,
            dir: self.dir.clone(),
        })
    }

    /// Map the input positions (stored for a deviation bound; read-only use).
    pub fn map_input(&self, n: usize) -> Result<Buf<DVec3>> {
        Buf::map_file(&self.path(INPUT), n)
    }

    /// The stored directed boundary edges (checked: every vertex in range).
    pub fn read_loops(&self, doc: &PlanDoc) -> Result<Vec<[u32; 2]>> {
        if doc.boundary_edges == 0 {
            return Ok(Vec::new());
        }
        let path = self.path(LOOPS);
        let edges: Buf<[u32; 2]> = Buf::map_file(&path, doc.boundary_edges)?;
        if edges.iter().flatten().any(|&v| v as usize >= doc.vertices) {
            return Err(Error::invalid(
                &path,
                "a boundary edge names a vertex out of range",
            ));
        }
        Ok(edges.to_vec())
    }

    /// Map the positions of `slot` (read-only use; private mapping).
    pub fn map_positions(&self, slot: u8, n: usize) -> Result<Buf<DVec3>> {
        Buf::map_file(&self.positions(slot), n)
    }

    /// Write `data`, the positions of vertices `first ..`, into `slot`, and sync them to disk.
    pub fn write_positions(&self, slot: u8, first: usize, data: &[DVec3]) -> Result<()> {
        let path = self.positions(slot);
        let write = || -> std::io::Result<()> {
            let f = OpenOptions::new().write(true).open(&path)?;
            f.write_all_at(
                as_bytes(data),
                (first * std::mem::size_of::<DVec3>()) as u64,
            )?;
            f.sync_data()
        };
        write().map_err(|e| Error::io(&path, e))
    }

    /// Remove the plan and checkpoint files (after a successful run without `--checkpoint`), and
    /// the directory if nothing else is in it.
    pub fn remove(&self) {
        for name in FILES {
            let _ = fs::remove_file(self.path(name));
        }
        let _ = fs::remove_dir(&self.dir);
    }
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<Option<T>> {
    match fs::read(path) {
        Ok(bytes) => serde_json::from_slice(&bytes)
            .map(Some)
            .map_err(|e| Error::invalid(path, format!("unreadable: {e}"))),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(Error::io(path, e)),
    }
}

fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<()> {
    crate::io::write_atomically(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value).map_err(std::io::Error::other)?;
        std::io::Write::write_all(w, b"\n")
    })
}
