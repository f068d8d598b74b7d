//! `GET /v1/events`: server-sent events that push every change of a job (queued, claimed,
//! progress, cancel requested, finished) so a dashboard follows cohorts, training and fits
//! live without polling each resource or reloading.
//!
//! Each subscriber reads the `job` table by modification time every half second; there is
//! no in-process bus because progress is committed by workers in the same transaction as
//! the work, so the table is the one place every change is visible, after any restart. A
//! stream first sends an `open` event, then a `job` event for every job still queued or
//! running, then one per change. It ends after five minutes (clients reconnect, and the
//! fetch or `EventSource` they use does so by itself) or when the service shuts down, so
//! no stream holds up a graceful shutdown.

use crate::db::states::JobStatus;
use std::collections::{HashMap, VecDeque};
use std::convert::Infallible;
use std::time::{Duration, Instant};

use axum::extract::State;
use axum::response::sse::{Event, KeepAlive, Sse};
use futures_util::stream::{self, Stream};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::AppState;
use super::jobs::JobView;
use crate::db::job_changes::{self, ChangedJob};
use crate::jobs::JobControls;

/// How often a subscriber looks for changes.
pub const POLL_INTERVAL: Duration = Duration::from_millis(500);

/// How long one stream lasts before the client is expected to reconnect.
pub const STREAM_LIFETIME: Duration = Duration::from_secs(300);

/// Rows read per look; more changes than this are read on the following looks.
const BATCH: i64 = 500;

pub(super) fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(get_events))
}

/// A stream of job changes (`text/event-stream`). Events: `open` (data `{}`), then `job`
/// for every job still queued or running, then `job` whenever one changes. Each `job`
/// event's data is the job as `GET /v1/jobs/{id}` shows it; its `subject` names the cohort,
/// model or anchor it works on. The stream ends after 5 minutes; reconnect to go on.
#[utoipa::path(get, path = "/v1/events", tag = "jobs",
    responses((status = 200, description = "Server-sent events (`open`, then `job` with a JobView as data)",
               content_type = "text/event-stream")))]
async fn get_events(
    State(state): State<AppState>,
) -> Sse<impl Stream<Item = Result<Event, Infallible>>> {
    let feed = JobFeed::new(state.pool.clone(), state.jobs.controls.clone());
    let events = stream::unfold(feed, |mut feed| async move {
        let event = feed.next_event().await?;
        Some((Ok(event), feed))
    });
    Sse::new(events).keep_alive(KeepAlive::default())
}

/// What a job looked like when it was last sent.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Fingerprint {
    status: JobStatus,
    done: i64,
    total: i64,
    cancel_requested: bool,
    updated_at: String,
}

impl Fingerprint {
    fn of(change: &ChangedJob) -> Self {
        Self {
            status: change.job.status,
            done: change.job.progress_done,
            total: change.job.progress_total,
            cancel_requested: change.job.cancel_requested.0,
            updated_at: change.updated_at.clone(),
        }
    }
}

/// One subscriber's position in the table and the events it has yet to send.
struct JobFeed {
    pool: crate::db::Pool,
    controls: JobControls,
    started: Instant,
    /// None until the first look; then the latest change seen.
    since: Option<String>,
    /// Jobs sent at the `since` instant, so a row read again is not sent twice.
    sent: HashMap<i64, Fingerprint>,
    pending: VecDeque<Event>,
}

impl JobFeed {
    fn new(pool: crate::db::Pool, controls: JobControls) -> Self {
        Self {
            pool,
            controls,
            started: Instant::now(),
            since: None,
            sent: HashMap::new(),
            pending: VecDeque::from([Event::default().event("open").data("{}")]),
        }
    }

    /// The next event to send, waiting for one; None ends the stream.
    async fn next_event(&mut self) -> Option<Event> {
        loop {
            if let Some(event) = self.pending.pop_front() {
                return Some(event);
            }
            if self.controls.is_shutting_down() || self.started.elapsed() >= STREAM_LIFETIME {
                return None;
            }
            if self.since.is_some() {
                tokio::time::sleep(POLL_INTERVAL).await;
            }
            if let Err(e) = self.look().await {
                tracing::warn!(error = %e, "event stream cannot read job changes");
            }
        }
    }

    /// Reads the jobs changed since the last look and queues an event for each new state.
    async fn look(&mut self) -> sqlx::Result<()> {
        let changes = match &self.since {
            None => {
                let latest = job_changes::latest_change(&self.pool).await?;
                self.since = Some(latest.unwrap_or_default());
                job_changes::active(&self.pool).await?
            }
            Some(since) => job_changes::changed_since(&self.pool, since, BATCH).await?,
        };
        for change in changes {
            let fingerprint = Fingerprint::of(&change);
            if self.sent.get(&change.job.job_id) == Some(&fingerprint) {
                continue;
            }
            if self.since.as_deref() < Some(change.updated_at.as_str()) {
                self.since = Some(change.updated_at.clone());
            }
            self.pending.push_back(job_event(change.job.clone().into()));
            self.sent.insert(change.job.job_id, fingerprint);
        }
        // Rows older than the cursor are never read again.
        let since = self.since.clone().unwrap_or_default();
        self.sent.retain(|_, f| f.updated_at >= since);
        Ok(())
    }
}

fn job_event(view: JobView) -> Event {
    let data = serde_json::to_string(&view).expect("job views serialise");
    Event::default().event("job").data(data)
}
