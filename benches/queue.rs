//! The task queue on its own: one job of many tiny tasks, claimed and completed by
//! concurrent claimers through the service's claim and commit statements, with no work in
//! between. Reports claims per second and the latency of a claim (p50, p99).
//!
//!     cargo bench --bench queue -- [TASKS] [CLAIMERS,...]
//!
//! `AORTAGEN_BENCH_DATABASE_URL` names the database (a PostgreSQL URL whose user may create
//! databases: a fresh one is made per run); unset, a temporary SQLite file.

use std::time::{Duration, Instant};

use aortagen::db::{self, states::JobKind, states::TaskKind, tasks::NewTask};

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    let tasks: i64 = args.first().map_or(Ok(2000), |a| a.parse())?;
    let claimers: Vec<usize> = match args.get(1) {
        Some(list) => list.split(',').map(str::parse).collect::<Result<_, _>>()?,
        None => vec![1, 4, 16],
    };
    let dir = tempfile::tempdir()?;
    let server = std::env::var("AORTAGEN_BENCH_DATABASE_URL").ok();
    println!("| backend | claimers | tasks | claims/s | claim p50 ms | claim p99 ms |");
    println!("|---|---|---|---|---|---|");
    for (run, &k) in claimers.iter().enumerate() {
        let url = match &server {
            Some(server) => fresh_postgres_database(server, run).await?,
            None => format!(
                "sqlite://{}",
                dir.path().join(format!("queue-{run}.db")).display()
            ),
        };
        let pool = db::connect(&url, (k + 2) as u32).await?;
        let mut tx = db::begin_write(&pool).await?;
        let job = db::jobs::enqueue(&mut tx, JobKind::Cohort, "{}", tasks).await?;
        let planned: Vec<NewTask> = (0..tasks)
            .map(|item| NewTask {
                kind: TaskKind::Shape,
                item,
            })
            .collect();
        db::tasks::insert_missing(&mut tx, job, &planned).await?;
        tx.commit().await?;

        let started = Instant::now();
        let handles: Vec<_> = (0..k)
            .map(|c| tokio::spawn(claim_until_empty(pool.clone(), format!("bench/{c}"))))
            .collect();
        let mut latencies = Vec::new();
        for h in handles {
            latencies.extend(h.await??);
        }
        let wall = started.elapsed();
        anyhow::ensure!(
            latencies.len() as i64 == tasks,
            "{} claims",
            latencies.len()
        );
        latencies.sort();
        let q = |p: f64| latencies[((latencies.len() - 1) as f64 * p).round() as usize];
        println!(
            "| {} | {k} | {tasks} | {:.0} | {:.2} | {:.2} |",
            db::Backend::of(&pool).name(),
            tasks as f64 / wall.as_secs_f64(),
            q(0.5).as_secs_f64() * 1e3,
            q(0.99).as_secs_f64() * 1e3,
        );
        pool.close().await;
    }
    Ok(())
}

/// Claims and completes tasks until none is left; returns each claim's latency.
async fn claim_until_empty(pool: db::Pool, owner: String) -> anyhow::Result<Vec<Duration>> {
    let mut latencies = Vec::new();
    for n in 0.. {
        let t = Instant::now();
        let Some(lease) = db::tasks::claim(&pool, &owner, &format!("{owner}/{n}"), 30_000).await?
        else {
            break;
        };
        latencies.push(t.elapsed());
        let mut tx = db::begin_write(&pool).await?;
        db::tasks::complete(&mut tx, &lease).await?;
        tx.commit().await?;
    }
    Ok(latencies)
}

async fn fresh_postgres_database(server: &str, run: usize) -> anyhow::Result<String> {
    let name = format!("queue_bench_{}_{run}", std::process::id());
    let admin = db::open(server, 1, &Default::default()).await?;
    sqlx::query(sqlx::AssertSqlSafe(format!("create database {name}")))
        .execute(&admin)
        .await?;
    admin.close().await;
    let (base, _) = server.rsplit_once('/').expect("a URL ending in /DATABASE");
    Ok(format!("{base}/{name}"))
}
