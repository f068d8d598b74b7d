//! Background priority for engine work, so the API keeps its latency while both cores
//! generate shapes or train.
//!
//! Heavy work runs on threads whose nice value is raised (lower priority): the rayon pool
//! that does the parallel numerics, and one short-lived thread per engine call. The Linux
//! scheduler then hands a core to an API thread as soon as it wakes, while idle cores still
//! go to the engine in full. Only raising a thread's nice value is allowed without
//! privileges, so engine work gets threads of its own instead of lowering pooled ones that
//! could not be restored.

use std::sync::atomic::{AtomicI32, Ordering};

/// Highest nice value Linux accepts.
pub const MAX_NICE: i32 = 19;

/// Nice value for engine threads; 0 leaves them at the process's priority.
static BACKGROUND_NICE: AtomicI32 = AtomicI32::new(0);

/// Sets the nice value used by [`spawn_background`] and the rayon pool from now on.
pub fn set_background_nice(nice: i32) {
    BACKGROUND_NICE.store(nice.clamp(0, MAX_NICE), Ordering::Relaxed);
}

/// The nice value engine threads get.
pub fn background_nice() -> i32 {
    BACKGROUND_NICE.load(Ordering::Relaxed)
}

/// Raises the calling thread's nice value to `nice` (never lowers it). On Linux a nice
/// value set by thread id applies to that thread alone.
/// Elsewhere it does nothing.
pub fn lower_current_thread(nice: i32) -> std::io::Result<()> {
    if nice <= 0 {
        return Ok(());
    }
    #[cfg(target_os = "linux")]
    {
        let tid = rustix::thread::gettid();
        let current = rustix::process::getpriority_process(Some(tid))?;
        if current < nice {
            rustix::process::setpriority_process(Some(tid), nice)?;
        }
    }
    Ok(())
}

/// The calling thread's nice value (Linux).
#[cfg(target_os = "linux")]
pub fn current_thread_nice() -> std::io::Result<i32> {
    let tid = rustix::thread::gettid();
    Ok(rustix::process::getpriority_process(Some(tid))?)
}

/// Builds rayon's global pool with threads at the background nice value. Must run before
/// anything uses rayon; if the pool already exists it is left as it is (and says so).
pub fn init_background_pool(nice: i32) {
    set_background_nice(nice);
    let nice = background_nice();
    let built = rayon::ThreadPoolBuilder::new()
        .thread_name(|i| format!("aortagen-engine-{i}"))
        .start_handler(move |_| {
            if let Err(e) = lower_current_thread(nice) {
                tracing::warn!(error = %e, "cannot lower an engine thread's priority");
            }
        })
        .build_global();
    if built.is_err() {
        tracing::warn!("the rayon pool was already running; its threads keep their priority");
    }
}

/// `spawn_blocking` for engine work: the closure runs, in the caller's span, on a thread of
/// its own at the background nice value. A panic reaches the handle as tokio's does.
pub fn spawn_background<F, R>(f: F) -> tokio::task::JoinHandle<R>
where
    F: FnOnce() -> R + Send + 'static,
    R: Send + 'static,
{
    let span = tracing::Span::current();
    let nice = background_nice();
    tokio::task::spawn_blocking(move || {
        std::thread::scope(|scope| {
            let worker = std::thread::Builder::new()
                .name("aortagen-job".into())
                .spawn_scoped(scope, move || {
                    if let Err(e) = lower_current_thread(nice) {
                        tracing::warn!(error = %e, "cannot lower a job thread's priority");
                    }
                    span.in_scope(f)
                })
                .expect("the OS refused a thread for engine work");
            match worker.join() {
                Ok(value) => value,
                Err(panic) => std::panic::resume_unwind(panic),
            }
        })
    })
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    #[test]
    fn lowering_raises_the_nice_value_of_this_thread_only() {
        std::thread::spawn(|| {
            let before = current_thread_nice().unwrap();
            let target = (before + 5).min(MAX_NICE);
            let sibling = std::thread::spawn(move || {
                lower_current_thread(target).unwrap();
                current_thread_nice().unwrap()
            });
            assert_eq!(sibling.join().unwrap(), target);
            assert_eq!(current_thread_nice().unwrap(), before, "caller unchanged");
            // Asking for a smaller value than the current one changes nothing.
            lower_current_thread(target).unwrap();
            lower_current_thread(target - 1).unwrap();
            assert_eq!(current_thread_nice().unwrap(), target);
        })
        .join()
        .unwrap();
    }

    #[tokio::test]
    async fn background_work_runs_niced_and_returns_its_value_or_its_panic() {
        let before = current_thread_nice().unwrap();
        let target = (before + 7).min(MAX_NICE);
        set_background_nice(target);
        let seen = spawn_background(current_thread_nice)
            .await
            .unwrap()
            .unwrap();
        assert_eq!(seen, target);
        let caller = std::thread::current().id();
        let other = spawn_background(move || std::thread::current().id() != caller);
        assert!(other.await.unwrap());
        let panicked = spawn_background(|| -> u8 { panic!("engine failure") }).await;
        assert!(panicked.unwrap_err().is_panic());
        set_background_nice(0);
    }
}
