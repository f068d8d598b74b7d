//! The HTTP/1 accept loop. axum's own `serve` sets no timer on its connections, so a client
//! that sends half a request header, or opens a connection and never speaks, holds a file
//! descriptor forever. Here every connection gets hyper's header-read timeout (which also
//! runs while a kept-alive connection waits for its next request), and the number of open
//! connections is bounded so slow clients cannot exhaust descriptors: at the bound, new
//! clients wait in the listen backlog until a connection closes.

use std::future::Future;
use std::io;
use std::pin::pin;
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use hyper::server::conn::http1;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore, watch};

use crate::config::Config;

/// How long clients may be slow and how many may be connected at once.
#[derive(Clone, Copy, Debug)]
pub struct ConnectionLimits {
    /// Longest wait for a request's complete header, counted from the moment the connection
    /// starts waiting for it (a new connection, or a kept-alive one after its last response).
    pub header_timeout: Duration,
    /// Most connections served at once.
    pub max_connections: usize,
}

impl ConnectionLimits {
    /// The limits the configuration asks for.
    pub fn from_config(config: &Config) -> Self {
        Self {
            header_timeout: Duration::from_secs(config.header_timeout_secs),
            max_connections: usize::try_from(config.max_connections).unwrap_or(usize::MAX),
        }
    }
}

/// Serves `router` on `listener` until `shutdown` completes, then stops accepting, lets every
/// open connection finish its request in flight and returns once all are closed.
pub async fn serve(
    listener: TcpListener,
    router: Router,
    limits: ConnectionLimits,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> io::Result<()> {
    let slots = Arc::new(Semaphore::new(limits.max_connections));
    let (closing_tx, closing_rx) = watch::channel(false);
    let mut shutdown = pin!(shutdown);
    loop {
        let slot = tokio::select! {
            slot = slots.clone().acquire_owned() => slot.expect("the semaphore is never closed"),
            () = &mut shutdown => break,
        };
        let stream = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, _peer)) => stream,
                Err(error) => {
                    pause_after_accept_error(&error).await;
                    continue;
                }
            },
            () = &mut shutdown => break,
        };
        let connection = serve_connection(
            stream,
            router.clone(),
            limits.header_timeout,
            closing_rx.clone(),
            slot,
        );
        tokio::spawn(connection);
    }
    drop(listener);
    let _ = closing_tx.send(true);
    // Every connection holds a slot until it closes: owning all slots means all are closed.
    let all = u32::try_from(limits.max_connections).unwrap_or(u32::MAX);
    let _ = slots.acquire_many(all).await;
    Ok(())
}

/// One client connection, closed gracefully once the server starts closing.
async fn serve_connection(
    stream: TcpStream,
    router: Router,
    header_timeout: Duration,
    mut closing: watch::Receiver<bool>,
    _slot: OwnedSemaphorePermit,
) {
    let _ = stream.set_nodelay(true);
    let mut builder = http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(header_timeout)
        .keep_alive(true);
    let service = TowerToHyperService::new(router);
    let mut connection = pin!(builder.serve_connection(TokioIo::new(stream), service));
    let finished = tokio::select! {
        outcome = connection.as_mut() => Some(outcome),
        _ = closing.wait_for(|closing| *closing) => None,
    };
    let outcome = match finished {
        Some(outcome) => outcome,
        None => {
            connection.as_mut().graceful_shutdown();
            connection.await
        }
    };
    if let Err(error) = outcome {
        // Timeouts, resets and malformed requests of one client are that client's business.
        tracing::debug!(error = %error, "connection ended with an error");
    }
}

/// Accept errors on one connection (reset before accept) are retried at once; errors of the
/// process (out of file descriptors) get a pause so the loop does not spin while they last.
async fn pause_after_accept_error(error: &io::Error) {
    use io::ErrorKind::{ConnectionAborted, ConnectionRefused, ConnectionReset};
    if matches!(
        error.kind(),
        ConnectionAborted | ConnectionRefused | ConnectionReset
    ) {
        return;
    }
    tracing::error!(error = %error, "cannot accept a connection; retrying in 1 s");
    tokio::time::sleep(Duration::from_secs(1)).await;
}
