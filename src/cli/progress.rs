//! The CLI's rendering of the library's [`Observer`]: an indicatif bar on stderr when stderr is a
//! terminal, nothing otherwise (batch jobs and pipes get clean logs).

use std::io::IsTerminal;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::engine::{IterationRecord, Observer};
use crate::smooth::Options;

/// Progress display for one command: a spinner for phases (reading, building topology, writing),
/// a bar for iterations.
pub struct Progress {
    bar: Option<ProgressBar>,
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
        Progress { bar: None }
    }

    fn visible() -> Self {
        let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
        Progress { bar: Some(bar) }
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
    pub fn iterations(&self, label: &str, total: usize) {
        if let Some(bar) = &self.bar {
            bar.disable_steady_tick();
            bar.set_message("");
            bar.reset();
            bar.set_style(
                ProgressStyle::with_template(
                    "{prefix} [{bar:24}] {pos}/{len} {msg} [{elapsed}, eta {eta}]",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
            );
            bar.set_prefix(label.to_string());
            bar.set_length(total as u64);
        }
    }

    /// Start the display of a run of `opts`: a bar of its iterations, or, when it stops
    /// automatically, a counter that shows the cap as a cap (the run may end long before it).
    pub fn smoothing(&self, opts: &Options) {
        if !opts.auto_stop {
            return self.iterations(opts.method.name(), opts.iterations);
        }
        if let Some(bar) = &self.bar {
            bar.disable_steady_tick();
            bar.set_message("");
            bar.reset();
            bar.set_style(
                ProgressStyle::with_template(
                    "{prefix}: iteration {pos} (stops when the noise is gone, at most {len}) {msg} [{elapsed}]",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            bar.set_prefix(opts.method.name());
            bar.set_length(opts.iterations as u64);
        }
    }

    /// Remove the display (before printing results).
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.finish();
    }
}

impl Observer for Progress {
    fn iteration(&mut self, record: &IterationRecord, _total: usize) {
        if let Some(bar) = &self.bar {
            bar.set_position(record.iteration as u64);
            if record.volume_pct.is_finite() {
                bar.set_message(format!("volume {:.6} %", record.volume_pct));
            }
        }
    }
}
