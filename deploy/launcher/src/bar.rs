//! The launcher's progress bar and what its line says.

use crate::Plan;

/// The run's progress bar (hidden with `--quiet`): episodes when the run has an episode limit,
/// else environment steps.
pub(super) fn progress_bar(plan: &Plan) -> indicatif::ProgressBar {
    if !plan.progress {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(match plan.cfg.episode_limit() {
        Some(n) => u64::from(n),
        None => plan.cfg.steps,
    });
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{elapsed_precise} [{bar:25}] {pos}/{len} episodes  {msg}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    bar
}

/// What the progress line says of demonstrations refused or answered late (nothing when none).
pub(super) fn demo_troubles(late: u64, refused: u64) -> String {
    let mut s = String::new();
    if late > 0 {
        s.push_str(&format!(" ({late} late)"));
    }
    if refused > 0 {
        s.push_str(&format!(" ({refused} REFUSED)"));
    }
    s
}
