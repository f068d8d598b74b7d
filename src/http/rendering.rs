//! Rendering of reports, plots and metrics off the async executor. A cohort's pairwise
//! matrix is n × n (10 000 numbers at 100 shapes): parsing it and writing it out as plots,
//! pages, CSV or JSON is CPU work that would hold up every request sharing the executor
//! thread. It runs on the blocking pool instead, a few renders at a time, so a burst of
//! report requests cannot take the whole pool from the other blocking work either.

use std::sync::OnceLock;

use tokio::sync::Semaphore;

use super::error::Result;
use crate::telemetry::spawn_blocking_with_span;

/// Renders in progress at once (others wait for a slot).
const CONCURRENT_RENDERS: usize = 2;

/// Runs `render` on the blocking pool once one of the service's render slots is free.
pub(super) async fn render_off_executor<T, F>(render: F) -> Result<T>
where
    F: FnOnce() -> Result<T> + Send + 'static,
    T: Send + 'static,
{
    static SLOTS: OnceLock<Semaphore> = OnceLock::new();
    let slots = SLOTS.get_or_init(|| Semaphore::new(CONCURRENT_RENDERS));
    run_in_slot(slots, render).await
}

/// Runs `render` on the blocking pool while holding one of `slots`.
async fn run_in_slot<T, F>(slots: &Semaphore, render: F) -> Result<T>
where
    F: FnOnce() -> Result<T> + Send + 'static,
    T: Send + 'static,
{
    let _slot = slots.acquire().await.map_err(anyhow::Error::from)?;
    spawn_blocking_with_span(render)
        .await
        .map_err(anyhow::Error::from)?
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;

    #[tokio::test(flavor = "current_thread")]
    async fn a_render_runs_on_another_thread_than_the_executor() {
        let executor = std::thread::current().id();
        let ran_on = render_off_executor(|| Ok(std::thread::current().id()))
            .await
            .unwrap();
        assert_ne!(ran_on, executor);
    }

    #[tokio::test]
    async fn a_render_holds_a_slot_while_it_runs() {
        let slots = Arc::new(Semaphore::new(2));
        let seen = slots.clone();
        let free_during = run_in_slot(&slots, move || Ok(seen.available_permits()))
            .await
            .unwrap();
        assert_eq!(
            free_during, 1,
            "one of the two slots is taken by the render"
        );
        assert_eq!(slots.available_permits(), 2, "and given back after it");
    }
}
