//! The dashboard's server side: the embedded page and its assets, `GET /v1/access`, shape
//! thumbnails rendered once and cached, and the server-sent stream of job changes.

use std::time::Duration;

use axum::http::{Method, StatusCode};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

use crate::helpers::{TestApp, cohort_body, spawn_app, spawn_app_configured};

#[tokio::test]
async fn the_page_and_its_assets_are_served_from_the_binary() {
    let app = spawn_app().await;
    let page = app.get("/").await;
    assert_eq!(page.status, StatusCode::OK);
    assert_eq!(
        page.header("content-type"),
        Some("text/html; charset=utf-8")
    );
    let csp = page.header("content-security-policy").unwrap();
    assert!(
        csp.contains("default-src 'self'") && csp.contains("frame-ancestors 'none'"),
        "{csp}"
    );
    let html = String::from_utf8(page.body.to_vec()).unwrap();
    assert!(html.contains(r#"src="/assets/app.js""#), "{html}");

    let script = app.get("/assets/app.js").await;
    assert_eq!(
        script.header("content-type"),
        Some("text/javascript; charset=utf-8")
    );
    assert!(script.body.len() > 10_000, "the bundle holds three.js");
    let style = app.get("/assets/app.css").await;
    assert_eq!(
        style.header("content-type"),
        Some("text/css; charset=utf-8")
    );

    let etag = script.header("etag").unwrap().to_owned();
    let again = app
        .request(
            Method::GET,
            "/assets/app.js",
            &[("if-none-match", &etag)],
            "",
        )
        .await;
    assert_eq!(again.status, StatusCode::NOT_MODIFIED);
    assert!(again.body.is_empty());
    assert_eq!(
        app.get("/assets/missing.js").await.status,
        StatusCode::NOT_FOUND
    );
}

#[tokio::test]
async fn with_protected_reads_the_page_is_public_and_says_what_needs_a_key() {
    let app = spawn_app_configured(|c| {
        c.api_keys = vec!["k-1".parse().unwrap()];
        c.protect_reads = true;
    })
    .await;
    assert_eq!(app.get("/").await.status, StatusCode::OK);
    assert_eq!(app.get("/assets/app.js").await.status, StatusCode::OK);
    let access = app.get("/v1/access").await;
    assert_eq!(access.status, StatusCode::OK);
    assert_eq!(
        access.json(),
        serde_json::json!({"writes_need_key": true, "reads_need_key": true})
    );
    assert_eq!(
        app.get("/v1/cohorts").await.status,
        StatusCode::UNAUTHORIZED
    );
    assert_eq!(app.get("/v1/events").await.status, StatusCode::UNAUTHORIZED);

    let open = spawn_app().await;
    let access = open.get("/v1/access").await.json();
    assert_eq!(
        access,
        serde_json::json!({"writes_need_key": false, "reads_need_key": false})
    );
}

async fn finished_shape(app: &TestApp) -> (i64, i64) {
    let cohort = app.create_cohort_ok(&cohort_body(2, 2)).await;
    app.run_pending_jobs().await;
    let shapes = app.shape_details(cohort).await;
    (cohort, shapes[0]["id"].as_i64().unwrap())
}

/// Width, height and RGB pixels of a PNG.
fn decode_png(bytes: &[u8]) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = decoder.read_info().unwrap();
    let mut pixels = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut pixels).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    pixels.truncate(info.buffer_size());
    (info.width, info.height, pixels)
}

#[tokio::test]
async fn a_thumbnail_is_rendered_once_and_then_served_from_the_cache() {
    let app = spawn_app().await;
    let (cohort, shape) = finished_shape(&app).await;
    let path = format!("/v1/shapes/{shape}/thumbnail.png");

    let first = app.get(&path).await;
    assert_eq!(first.status, StatusCode::OK);
    assert_eq!(first.header("content-type"), Some("image/png"));
    let (width, height, pixels) = decode_png(&first.body);
    assert_eq!((width, height), (256, 256));
    // The shape covers the middle of the picture; the corners are the white background.
    let at = |x: u32, y: u32| &pixels[3 * (y * width + x) as usize..][..3];
    assert_eq!(at(0, 0), [255, 255, 255]);
    assert_ne!(at(128, 128), [255, 255, 255]);
    assert_eq!(app.count("shape_thumbnail").await, 1);

    // What is cached is what is served: plant other bytes for the same mesh digest.
    let sha: String = sqlx::query_scalar("select mesh_sha256 from shape where shape_id = $1")
        .bind(shape)
        .fetch_one(&app.state.pool)
        .await
        .unwrap();
    aortagen::db::thumbnails::put(&app.state.pool, shape, &sha, 256, b"planted")
        .await
        .unwrap();
    assert_eq!(&app.get(&path).await.body[..], b"planted");
    assert_eq!(app.count("shape_thumbnail").await, 1);

    let etag = first.header("etag").unwrap().to_owned();
    let cached = app
        .request(Method::GET, &path, &[("if-none-match", &etag)], "")
        .await;
    assert_eq!(cached.status, StatusCode::NOT_MODIFIED);
    assert_eq!(
        app.get("/v1/shapes/999/thumbnail.png").await.status,
        StatusCode::NOT_FOUND
    );

    let deleted = app
        .request(Method::DELETE, &format!("/v1/cohorts/{cohort}"), &[], "")
        .await;
    assert_eq!(deleted.status, StatusCode::NO_CONTENT);
    assert_eq!(
        app.count("shape_thumbnail").await,
        0,
        "removed with its shape"
    );
}

/// Reads the raw event stream until `needle` appears (or the time is up).
async fn read_until(stream: &mut TcpStream, seen: &mut String, needle: &str) -> bool {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(10);
    let mut buf = [0u8; 4096];
    while !seen.contains(needle) {
        match tokio::time::timeout_at(deadline, stream.read(&mut buf)).await {
            Ok(Ok(n)) if n > 0 => seen.push_str(&String::from_utf8_lossy(&buf[..n])),
            _ => return false,
        }
    }
    true
}

#[tokio::test]
async fn the_event_stream_pushes_a_cohort_from_queued_to_succeeded() {
    let app = spawn_app().await;
    let before = app.create_cohort_ok(&cohort_body(1, 2)).await;
    let host = app.address.trim_start_matches("http://");
    let mut stream = TcpStream::connect(host).await.unwrap();
    let request =
        format!("GET /v1/events HTTP/1.1\r\nHost: {host}\r\nAccept: text/event-stream\r\n\r\n");
    stream.write_all(request.as_bytes()).await.unwrap();
    let mut seen = String::new();

    assert!(
        read_until(&mut stream, &mut seen, "event: open").await,
        "{seen}"
    );
    assert!(seen.contains("content-type: text/event-stream"), "{seen}");
    // A job queued before the subscription is announced at once.
    let queued_before = r#""status":"queued","progress":{"done":0,"total":1}"#;
    assert!(
        read_until(&mut stream, &mut seen, queued_before).await,
        "{seen}"
    );
    assert!(
        seen.contains(&format!(r#""subject":"/v1/cohorts/{before}""#)),
        "{seen}"
    );

    let cohort = app.create_cohort_ok(&cohort_body(2, 2)).await;
    let subject = format!(r#""subject":"/v1/cohorts/{cohort}""#);
    assert!(read_until(&mut stream, &mut seen, &subject).await, "{seen}");
    app.run_pending_jobs().await;
    let done = r#""status":"succeeded","progress":{"done":2,"total":2},"#;
    assert!(read_until(&mut stream, &mut seen, done).await, "{seen}");

    // Each state is sent once: the finished state of the second cohort appears a single time.
    tokio::time::sleep(Duration::from_millis(1200)).await;
    let mut tail = String::new();
    read_until(&mut stream, &mut tail, "never sent").await;
    seen.push_str(&tail);
    let finished = seen
        .split("\n\n")
        .filter(|e| e.contains(&subject) && e.contains(r#""status":"succeeded""#))
        .count();
    assert_eq!(finished, 1, "{seen}");
}
