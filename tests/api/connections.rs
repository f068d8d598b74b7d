//! Connection limits: clients that send half a request header, or connect and never speak,
//! are disconnected after the header timeout, and open connections are bounded, so slow
//! clients cannot hold file descriptors until the service stops answering.

use std::time::Duration;

use axum::http::StatusCode;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

use crate::helpers::{TestApp, spawn_app_configured};

/// Generous bound on how long a test waits for the server to act; not a figure under test.
const PATIENCE: Duration = Duration::from_secs(20);

async fn connect(app: &TestApp) -> TcpStream {
    TcpStream::connect(app.address.trim_start_matches("http://"))
        .await
        .unwrap()
}

/// Reads until the server closes the connection; `None` if it is still open after `wait`.
async fn read_until_closed(stream: &mut TcpStream, wait: Duration) -> Option<Vec<u8>> {
    let mut received = Vec::new();
    match tokio::time::timeout(wait, stream.read_to_end(&mut received)).await {
        Ok(_) => Some(received),
        Err(_) => None,
    }
}

#[tokio::test]
async fn connections_with_an_unfinished_header_are_closed() {
    let app = spawn_app_configured(|c| c.header_timeout_secs = 1).await;
    let mut slow = Vec::new();
    for _ in 0..20 {
        let mut stream = connect(&app).await;
        stream
            .write_all(b"GET /healthz HTTP/1.1\r\nhost: localhost\r\nx-slow: ")
            .await
            .unwrap();
        slow.push(stream);
    }
    for stream in &mut slow {
        let received = read_until_closed(stream, PATIENCE).await;
        let received = received.expect("the server closes a connection whose header never ends");
        // Whatever the server says on the way out, it never answers the unfinished request.
        assert!(!String::from_utf8_lossy(&received).contains("200 OK"));
    }
    assert_eq!(app.get("/healthz").await.status, StatusCode::OK);
}

#[tokio::test]
async fn connections_that_never_send_anything_are_closed() {
    let app = spawn_app_configured(|c| c.header_timeout_secs = 1).await;
    let mut silent = connect(&app).await;
    let received = read_until_closed(&mut silent, PATIENCE).await;
    assert!(received.is_some(), "an idle connection is closed");
}

#[tokio::test]
async fn clients_beyond_the_connection_bound_wait_for_a_free_slot() {
    let app = spawn_app_configured(|c| {
        c.max_connections = 2;
        c.header_timeout_secs = 600;
    })
    .await;
    let first = connect(&app).await;
    let _second = connect(&app).await;
    let mut third = connect(&app).await;
    third
        .write_all(b"GET /healthz HTTP/1.1\r\nhost: localhost\r\nconnection: close\r\n\r\n")
        .await
        .unwrap();
    assert!(
        read_until_closed(&mut third, Duration::from_millis(700))
            .await
            .is_none(),
        "with both slots held, the third client is not served"
    );
    drop(first);
    let answer = read_until_closed(&mut third, PATIENCE)
        .await
        .expect("a closed connection frees its slot for the waiting client");
    assert!(String::from_utf8_lossy(&answer).starts_with("HTTP/1.1 200"));
}
