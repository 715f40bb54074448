//! What a run tells an observer of its phases (`Observer::phase_start` / `phase_end`): every
//! phase of a file run, in memory and in scratch files, and of an in-memory run, in order, each
//! with a meter that only grows, never passes its total, and ends at it.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use vcsmooth::engine::{self, EngineSettings, IterationRecord, Meter, Observer, Phase, Quiet};
use vcsmooth::{Method, Options};

use crate::util::noisy_sphere;

/// One phase as the recorder saw it.
#[derive(Debug)]
struct Seen {
    phase: Phase,
    /// The meter's (done, total) when the phase began, while it ran (sampled from another thread,
    /// as a display reads it), and when it ended.
    start: (u64, u64),
    samples: Vec<(u64, u64)>,
    end: (u64, u64),
}

/// The phase under way: its meter, and the thread sampling it until told to stop.
struct Running {
    phase: Phase,
    meter: Arc<Meter>,
    stop: Arc<AtomicBool>,
    sampler: JoinHandle<Vec<(u64, u64)>>,
}

/// Records the phases and samples each meter from its own thread while the phase runs.
#[derive(Default)]
struct Recorder {
    seen: Vec<Seen>,
    running: Option<Running>,
    iterations: Vec<usize>,
    /// The parts told within iterations (`Some((done, of))`) and each iteration's end (`None`).
    log: Vec<Option<(usize, usize)>>,
}

impl Observer for Recorder {
    fn phase_start(&mut self, phase: Phase, meter: &Arc<Meter>) {
        assert!(
            self.running.is_none(),
            "{phase:?} began inside another phase"
        );
        let stop = Arc::new(AtomicBool::new(false));
        let sampler = {
            let (meter, stop) = (Arc::clone(meter), Arc::clone(&stop));
            std::thread::spawn(move || {
                let mut samples = Vec::new();
                while !stop.load(Ordering::Acquire) {
                    samples.push((meter.done(), meter.total()));
                    std::thread::sleep(Duration::from_micros(200));
                }
                samples
            })
        };
        let start = (meter.done(), meter.total());
        self.running = Some(Running {
            phase,
            meter: Arc::clone(meter),
            stop,
            sampler,
        });
        self.seen.push(Seen {
            phase,
            start,
            samples: Vec::new(),
            end: (0, 0),
        });
    }

    fn phase_end(&mut self, phase: Phase) {
        let Running {
            phase: began,
            meter,
            stop,
            sampler,
        } = self.running.take().expect("a phase ended unbegun");
        assert_eq!(began, phase, "phase_end names another phase");
        stop.store(true, Ordering::Release);
        let seen = self.seen.last_mut().unwrap();
        seen.samples = sampler.join().unwrap();
        seen.end = (meter.done(), meter.total());
    }

    fn iteration(&mut self, record: &IterationRecord, _total: usize) {
        let phase = self.running.as_ref().map(|r| r.phase);
        assert_eq!(
            phase,
            Some(Phase::Smooth),
            "an iteration outside the smoothing phase"
        );
        self.iterations.push(record.iteration);
        self.log.push(None);
    }

    fn iteration_part(&mut self, done: usize, of: usize) {
        self.log.push(Some((done, of)));
    }
}

impl Recorder {
    /// The phases seen, in order, after checking each one's meter.
    fn phases(&self) -> Vec<Phase> {
        assert!(self.running.is_none(), "a phase never ended");
        for s in &self.seen {
            let p = s.phase;
            assert_eq!(s.start.0, 0, "{p:?} began with work done");
            let mut done = 0;
            for &(d, total) in &s.samples {
                assert!(d >= done, "{p:?}: the count went back from {done} to {d}");
                // A write's total is an estimate until it ends (a text file's size).
                if p != Phase::Write {
                    assert!(d <= total, "{p:?}: {d} done of {total}");
                    assert_eq!(total, s.start.1, "{p:?}: the total changed");
                }
                done = d;
            }
            assert!(s.end.0 >= done, "{p:?}: ended below a count seen");
            assert_eq!(
                s.end.0, s.end.1,
                "{p:?}: ended at {} of {}",
                s.end.0, s.end.1
            );
            assert!(s.end.1 > 0, "{p:?}: nothing to count");
        }
        self.seen.iter().map(|s| s.phase).collect()
    }

    fn total(&self, phase: Phase) -> u64 {
        self.seen.iter().find(|s| s.phase == phase).unwrap().end.1
    }
}

fn run_file(
    input: &Path,
    output: &Path,
    opts: &Options,
    settings: &EngineSettings,
) -> (Recorder, engine::Report) {
    let mut recorder = Recorder::default();
    let report = engine::run_file(input, output, opts, settings, &mut recorder).unwrap();
    assert_eq!(
        recorder.iterations,
        (1..=report.iterations_run).collect::<Vec<_>>()
    );
    (recorder, report)
}

/// A file run tells every phase in order, in memory and in scratch files (the smallest budget, on
/// a sphere whose estimate exceeds it; the input read again after smoothing), with meters that end
/// at their totals: the reads at the input's size, the write at the output's; and the outputs are
/// those of a run nobody watches.
#[test]
fn a_file_run_reports_each_phase_to_its_end() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.ply");
    // Level 8 (1.3M triangles) is the smallest sphere whose in-core estimate exceeds the 64M
    // minimum budget; many chunks of every loop.
    let mesh = noisy_sphere(8, 0.3, 5);
    vcsmooth::io::write_mesh(&input, &mesh).unwrap();
    let opts = Options {
        method: Method::Laplacian,
        iterations: 2,
        ..Options::default()
    };
    let in_memory = EngineSettings {
        threads: Some(2),
        with_stats: true,
        ..EngineSettings::default()
    };
    // Both measure their input and output: the statistics' meters count the vertices measured
    // (out of core the output is measured in a phase of its own).
    let scratch = EngineSettings {
        memory_budget: Some(64 << 20),
        scratch: Some(dir.path().to_path_buf()),
        ..in_memory.clone()
    };
    let quiet = dir.path().join("quiet.ply");
    engine::run_file(&input, &quiet, &opts, &in_memory, &mut Quiet).unwrap();
    let size = |p: &Path| std::fs::metadata(p).unwrap().len();
    for (name, settings) in [("heap", &in_memory), ("scratch", &scratch)] {
        let output = dir.path().join(format!("{name}.ply"));
        let (seen, report) = run_file(&input, &output, &opts, settings);
        assert_eq!(report.memory.storage, name);
        // A run that measures its input counts the components as the reorder sorts the
        // triangles (no phase of their own), and the rest after the topology is built.
        let mut want = vec![
            Phase::Read,
            Phase::Reorder,
            Phase::Topology,
            Phase::Schedule,
        ];
        if settings.with_stats {
            want.push(Phase::Statistics);
        }
        want.push(Phase::Smooth);
        if name == "scratch" {
            // Out of core the output (a `float` PLY) is measured before the positions are put
            // back in the input's order, and the input's triangles are read again for the write
            // once the plan is given back.
            if settings.with_stats {
                want.push(Phase::Statistics);
            }
            want.extend([Phase::Restore, Phase::Read]);
        } else {
            want.push(Phase::Restore);
        }
        want.push(Phase::Write);
        assert_eq!(seen.phases(), want, "{name}");
        assert_eq!(seen.total(Phase::Read), size(&input), "{name}");
        assert_eq!(seen.total(Phase::Write), size(&output), "{name}");
        assert_eq!(seen.total(Phase::Smooth), 2, "{name}");
        assert_eq!(
            seen.total(Phase::Restore),
            mesh.positions.len() as u64,
            "{name}"
        );
        assert!(
            std::fs::read(&output).unwrap() == std::fs::read(&quiet).unwrap(),
            "{name}: the output differs from an unobserved run's"
        );
    }
}

/// An output in another format than the input's: the write's estimate is corrected to the size
/// written. The automatic stop ends its phase at the cap even when it stops sooner.
#[test]
fn a_write_in_another_format_ends_at_its_size_and_an_automatic_stop_at_its_cap() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.ply");
    vcsmooth::io::write_mesh(&input, &noisy_sphere(5, 0.3, 2)).unwrap();
    let output = dir.path().join("out.obj");
    let opts = Options {
        method: Method::Taubin,
        iterations: 200,
        auto_stop: true,
        ..Options::default()
    };
    let (seen, _) = run_file(&input, &output, &opts, &EngineSettings::default());
    assert_eq!(seen.phases().last(), Some(&Phase::Write));
    assert_eq!(
        seen.total(Phase::Write),
        std::fs::metadata(&output).unwrap().len()
    );
    assert!(seen.iterations.len() < 200, "the stop never came");
    assert_eq!(seen.total(Phase::Smooth), 200);
}

/// A stencil method's iterations tell their parts (the colours of the sweep), in order, each
/// iteration all of them before its record: what lets a display move within a long iteration.
#[test]
fn iterations_tell_their_colours_as_they_go() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.ply");
    vcsmooth::io::write_mesh(&input, &noisy_sphere(5, 0.3, 2)).unwrap();
    let output = dir.path().join("out.ply");
    let settings = EngineSettings {
        patch_size: 64,
        ..EngineSettings::default()
    };
    for method in [Method::Vcs, Method::VcsLowpass] {
        let opts = Options {
            method,
            iterations: 3,
            ..Options::default()
        };
        let (seen, report) = run_file(&input, &output, &opts, &settings);
        let colours = report.plan.colours;
        assert!(colours > 1, "{method}: {colours} colours");
        let per_iteration: Vec<Option<(usize, usize)>> = (1..=colours)
            .map(|c| Some((c, colours)))
            .chain([None])
            .collect();
        assert_eq!(seen.log, per_iteration.repeat(3), "{method}");
    }
}

/// An in-memory run has no read and no write; it puts the positions back in the caller's order.
#[test]
fn an_in_memory_run_reports_its_planning_and_smoothing() {
    let mut mesh = noisy_sphere(6, 0.3, 3);
    let mut recorder = Recorder::default();
    let settings = EngineSettings {
        with_stats: true,
        ..EngineSettings::default()
    };
    let opts = Options::default();
    engine::smooth_with(&mut mesh, &opts, &settings, &mut recorder).unwrap();
    assert_eq!(
        recorder.phases(),
        [
            Phase::Reorder,
            Phase::Topology,
            Phase::Schedule,
            Phase::Statistics,
            Phase::Smooth,
            Phase::Restore
        ]
    );
    assert_eq!(recorder.total(Phase::Smooth), opts.iterations as u64);
    assert_eq!(recorder.total(Phase::Restore), mesh.positions.len() as u64);
}

/// In a pipe (a batch log) nothing is drawn: stderr stays empty.
#[test]
fn nothing_is_drawn_in_a_pipe() {
    let dir = tempfile::tempdir().unwrap();
    let (input, output) = (dir.path().join("in.ply"), dir.path().join("out.ply"));
    vcsmooth::io::write_mesh(&input, &noisy_sphere(4, 0.3, 1)).unwrap();
    let o = crate::util::vcsmooth([
        "smooth".as_ref(),
        input.as_os_str(),
        output.as_os_str(),
        "--report".as_ref(),
        dir.path().join("r.json").as_os_str(),
    ]);
    crate::util::ok(o.clone());
    assert!(o.stderr.is_empty(), "{}", crate::util::stderr(&o));
}
