//! Progress for long commands: an indicatif bar when stderr is a terminal, structured
//! `tracing` log lines otherwise (CI logs, services, redirected output).

use std::io::IsTerminal;

use indicatif::{ProgressBar, ProgressStyle};

/// Installs a stderr log subscriber (filter from `RUST_LOG`, default `info`) unless one is set.
pub fn init_logging() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .try_init();
}

/// A bar of `len` units with an ETA when stderr is a terminal, `None` otherwise.
pub fn terminal_bar(len: u64, unit: &str) -> Option<ProgressBar> {
    if !std::io::stderr().is_terminal() {
        return None;
    }
    let template =
        format!("{{elapsed_precise}} [{{bar:30}}] {{pos}}/{{len}} {unit} (ETA {{eta}}) {{msg}}");
    let style = ProgressStyle::with_template(&template)
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ");
    Some(ProgressBar::new(len).with_style(style))
}
