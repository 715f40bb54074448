//! The CLI's rendering of the library's [`Observer`]: an indicatif bar on stderr when stderr is a
//! terminal, nothing otherwise (batch jobs and pipes get clean logs).

use std::io::IsTerminal;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use indicatif::{HumanDuration, ProgressBar, ProgressDrawTarget, ProgressState, ProgressStyle};

use crate::engine::{IterationRecord, Meter, Observer, Phase};
use crate::smooth::Options;

/// Progress display for one command: a spinner for steps that report no progress, a bar with
/// percentage and time left for the library's phases (reading, reordering, topology, colouring,
/// statistics, restoring the input order, writing), a bar for iterations.
pub struct Progress {
    bar: Option<ProgressBar>,
    /// The iteration bar that [`Progress::smoothing`] or [`Progress::iterations`] asked for, drawn
    /// again when a run's smoothing phase begins (the phases before it take the bar over).
    iterations: Option<IterationBar>,
    /// Copies the current phase's meter into the bar.
    ticker: Option<Ticker>,
    /// Iterations done in the current smoothing phase.
    iterations_done: u64,
}

/// Steps of the iteration bar per iteration: it moves within an iteration as its parts (the
/// colours of a stencil sweep) are done.
const STEPS: u64 = 1000;

/// An iteration bar: its label, its length, whether the run stops by itself before it.
#[derive(Clone)]
struct IterationBar {
    label: String,
    total: usize,
    auto_stop: bool,
}

/// How often a phase's bar reads its meter.
const TICK: Duration = Duration::from_millis(100);

/// A thread that copies a phase's meter into the bar every [`TICK`]: the library's loops only bump
/// the meter's counters, and the drawing stays here.
struct Ticker {
    stop: Arc<AtomicBool>,
    thread: JoinHandle<()>,
}

impl Ticker {
    fn start(bar: ProgressBar, meter: Arc<Meter>) -> Ticker {
        let stop = Arc::new(AtomicBool::new(false));
        let stopped = Arc::clone(&stop);
        let thread = std::thread::spawn(move || {
            loop {
                // Checked before the copy, so that the last copy shows the phase's end.
                let last = stopped.load(Ordering::Acquire);
                bar.set_length(meter.total());
                bar.set_position(meter.done());
                if last {
                    break;
                }
                std::thread::park_timeout(TICK);
            }
        });
        Ticker { stop, thread }
    }

    fn stop(self) {
        self.stop.store(true, Ordering::Release);
        self.thread.thread().unpark();
        let _ = self.thread.join();
    }
}

impl Progress {
    /// A display on stderr if it is a terminal, otherwise a silent one.
    pub fn for_stderr() -> Self {
        if std::io::stderr().is_terminal() {
            Self::visible()
        } else {
            Self::hidden()
        }
    }

    /// A display that draws nothing.
    pub fn hidden() -> Self {
        Progress {
            bar: None,
            iterations: None,
            ticker: None,
            iterations_done: 0,
        }
    }

    fn visible() -> Self {
        let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
        Progress {
            bar: Some(bar),
            iterations: None,
            ticker: None,
            iterations_done: 0,
        }
    }

    /// Show that a phase (e.g. "reading in.ply") is under way.
    pub fn phase(&self, message: impl Into<String>) {
        if let Some(bar) = &self.bar {
            bar.set_style(
                ProgressStyle::with_template("{spinner} {msg} [{elapsed}]")
                    .unwrap_or_else(|_| ProgressStyle::default_spinner()),
            );
            bar.unset_length();
            bar.set_message(message.into());
            bar.enable_steady_tick(Duration::from_millis(120));
        }
    }

    /// Start a bar of `total` iterations labelled `label` (e.g. the method's name).
    pub fn iterations(&mut self, label: &str, total: usize) {
        self.iterations = Some(IterationBar {
            label: label.to_string(),
            total,
            auto_stop: false,
        });
        self.draw_iterations();
    }

    /// Start the display of a run of `opts`: a bar of its iterations, or, when it stops
    /// automatically, a counter that shows the cap as a cap (the run may end long before it).
    pub fn smoothing(&mut self, opts: &Options) {
        self.iterations = Some(IterationBar {
            label: opts.method.name().to_string(),
            total: opts.iterations,
            auto_stop: opts.auto_stop,
        });
        self.draw_iterations();
    }

    /// Draw the iteration bar asked for last.
    fn draw_iterations(&mut self) {
        if let Some(it) = self.iterations.clone() {
            self.draw(&it);
        }
    }

    /// Draw an iteration bar.
    fn draw(&mut self, it: &IterationBar) {
        let style = if it.auto_stop {
            ProgressStyle::with_template(
                "{prefix}: iteration {done} (stops when the noise is gone, at most {cap}) {msg} [{elapsed}]",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar())
        } else {
            with_eta(ProgressStyle::with_template(
                "{prefix} [{bar:24}] {done}/{cap} {msg} [{elapsed}, eta {eta}]",
            ))
        }
        // Whole iterations, from the bar's steps.
        .with_key("done", |state: &ProgressState, w: &mut dyn std::fmt::Write| {
            let _ = write!(w, "{}", state.pos() / STEPS);
        })
        .with_key("cap", |state: &ProgressState, w: &mut dyn std::fmt::Write| {
            let _ = write!(w, "{}", state.len().unwrap_or(0) / STEPS);
        });
        self.iterations_done = 0;
        if let Some(bar) = self.replace_bar(
            style,
            it.label.clone(),
            (it.total as u64).saturating_mul(STEPS),
        ) {
            bar.tick();
        }
    }

    /// Show a phase of the library as a bar of its meter, with its percentage, the time it has
    /// taken and the time left.
    fn draw_phase(&mut self, phase: Phase, meter: &Arc<Meter>) {
        let style = with_eta(ProgressStyle::with_template(
            "{prefix} [{bar:24}] {percent:>3}% [{elapsed}, eta {eta}]",
        ));
        let Some(bar) = self.replace_bar(style, phase.name().to_string(), meter.total()) else {
            return;
        };
        bar.set_position(meter.done());
        // Redrawn even while the meter stands still (a sort), so that the time keeps going.
        bar.enable_steady_tick(Duration::from_millis(120));
        self.ticker = Some(Ticker::start(bar, Arc::clone(meter)));
    }

    /// Put a new bar in the place of the current one (if the display is visible): set up before
    /// it draws, so that no frame mixes the old bar's label, position or time with the new one's,
    /// and its elapsed time and time left start from zero.
    fn replace_bar(
        &mut self,
        style: ProgressStyle,
        label: String,
        len: u64,
    ) -> Option<ProgressBar> {
        let old = self.bar.as_ref()?;
        let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr())
            .with_style(style)
            .with_prefix(label);
        old.finish_and_clear();
        self.bar = Some(bar.clone());
        Some(bar)
    }

    fn stop_ticker(&mut self) {
        if let Some(ticker) = self.ticker.take() {
            ticker.stop();
        }
    }

    /// Remove the display (before printing results).
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

/// A bar's style whose `{eta}` says "unknown" until there is progress to estimate it from
/// (indicatif shows `0s` then, which reads as "done").
fn with_eta(template: Result<ProgressStyle, indicatif::style::TemplateError>) -> ProgressStyle {
    template
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ")
        .with_key(
            "eta",
            |state: &ProgressState, w: &mut dyn std::fmt::Write| {
                let _ = match state.pos() {
                    0 => w.write_str("unknown"),
                    _ => write!(w, "{:#}", HumanDuration(state.eta())),
                };
            },
        )
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.stop_ticker();
        self.finish();
    }
}

impl Observer for Progress {
    fn phase_start(&mut self, phase: Phase, meter: &Arc<Meter>) {
        self.stop_ticker();
        if phase != Phase::Smooth {
            return self.draw_phase(phase, meter);
        }
        // The iterations report themselves (`iteration`), on the bar the command asked for, or
        // on a plain one.
        let it = self.iterations.clone().unwrap_or_else(|| IterationBar {
            label: phase.name().to_string(),
            total: meter.total() as usize,
            auto_stop: false,
        });
        self.draw(&it);
    }

    fn phase_end(&mut self, _phase: Phase) {
        self.stop_ticker();
    }

    fn iteration_part(&mut self, done: usize, of: usize) {
        if let Some(bar) = &self.bar {
            let within = done as u64 * STEPS / of.max(1) as u64;
            bar.set_position(
                self.iterations_done
                    .saturating_mul(STEPS)
                    .saturating_add(within.min(STEPS - 1)),
            );
        }
    }

    fn iteration(&mut self, record: &IterationRecord, _total: usize) {
        self.iterations_done = record.iteration as u64;
        if let Some(bar) = &self.bar {
            bar.set_position((record.iteration as u64).saturating_mul(STEPS));
            if record.volume_pct.is_finite() {
                bar.set_message(format!("volume {:.6} %", record.volume_pct));
            }
        }
    }
}
