//! Progress bars for long stages: drawn on stderr when it is a terminal, hidden otherwise.
use std::io::IsTerminal;

use indicatif::{ProgressBar, ProgressStyle};

/// A bar of `len` steps labelled `label`; hidden when stderr is not a terminal.
pub fn bar(len: u64, label: &str) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(len);
    pb.set_style(
        ProgressStyle::with_template("{msg:>12} [{bar:30}] {pos}/{len} {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    pb.set_message(label.to_string());
    pb
}

/// A spinner for a step of unknown length; hidden when stderr is not a terminal.
pub fn spinner(label: &str) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new_spinner();
    pb.set_message(label.to_string());
    pb.enable_steady_tick(std::time::Duration::from_millis(120));
    pb
}

/// Runs `work` under a bar of `len` named steps labelled `label`: each call of the callback
/// `work` gets names the step that starts and advances the bar.
pub fn stepped<T>(len: u64, label: &str, work: impl FnOnce(&dyn Fn(&str)) -> T) -> T {
    let pb = bar(len, label);
    let out = work(&|step| {
        pb.set_message(step.to_string());
        pb.inc(1);
    });
    pb.finish_and_clear();
    out
}
