//! The real `aortagen serve` process for crash and shutdown tests: a temporary database and
//! models directory holding a copy of the bundled model, start/kill/terminate, and a small
//! blocking HTTP client (one request per connection, so nothing outlives a killed server).

#![allow(dead_code)]

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

/// Where a service keeps its state across restarts.
pub struct ServiceDir {
    /// Holds the database, the models and the logs.
    pub dir: tempfile::TempDir,
    starts: usize,
    /// Extra environment of every start.
    pub env: Vec<(String, String)>,
}

impl ServiceDir {
    /// A fresh directory with the bundled model copied to `models/default`.
    pub fn new() -> Self {
        let dir = tempfile::tempdir().expect("temp dir");
        let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/default");
        let target = dir.path().join("models/default");
        std::fs::create_dir_all(&target).expect("models dir");
        for entry in std::fs::read_dir(&source).expect("bundled model") {
            let entry = entry.expect("bundled model entry");
            std::fs::copy(entry.path(), target.join(entry.file_name())).expect("copy model");
        }
        Self {
            dir,
            starts: 0,
            env: Vec::new(),
        }
    }

    /// The SQLite file.
    pub fn database(&self) -> PathBuf {
        self.dir.path().join("aortagen.db")
    }

    /// Starts `aortagen serve` on a free port and waits until it answers /readyz.
    pub fn start(&mut self, workers: usize) -> Server {
        let port = free_port();
        let log_path = self.dir.path().join(format!("serve-{}.log", self.starts));
        self.starts += 1;
        let log = std::fs::File::create(&log_path).expect("log file");
        let child = Command::new(env!("CARGO_BIN_EXE_aortagen"))
            .arg("serve")
            .env("AORTAGEN_BIND", format!("127.0.0.1:{port}"))
            .env(
                "AORTAGEN_DATABASE_URL",
                format!("sqlite://{}", self.database().display()),
            )
            .env("AORTAGEN_MODELS_DIR", self.dir.path().join("models"))
            .env("AORTAGEN_WORKERS", workers.to_string())
            .env("AORTAGEN_REQUEST_TIMEOUT_SECS", "60")
            .env("RUST_LOG", "aortagen=info")
            .envs(self.env.iter().map(|(k, v)| (k, v)))
            .stdin(Stdio::null())
            .stdout(log.try_clone().expect("log handle"))
            .stderr(log)
            .spawn()
            .expect("aortagen starts");
        let mut server = Server {
            child,
            port,
            log_path,
        };
        server.wait_ready(Duration::from_secs(120));
        server
    }
}

/// A running `aortagen serve`.
pub struct Server {
    child: Child,
    /// Its port on 127.0.0.1.
    pub port: u16,
    /// Its combined stdout and stderr.
    pub log_path: PathBuf,
}

impl Server {
    fn wait_ready(&mut self, timeout: Duration) {
        let start = Instant::now();
        loop {
            if let Some(status) = self.child.try_wait().expect("child status") {
                panic!(
                    "aortagen exited with {status} before serving:\n{}",
                    self.log()
                );
            }
            if let Ok(r) = self.try_request("GET", "/readyz", &[], &[])
                && r.status == 200
            {
                return;
            }
            assert!(
                start.elapsed() < timeout,
                "aortagen not ready after {timeout:?}:\n{}",
                self.log()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// The server's log so far.
    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log_path).unwrap_or_default()
    }

    /// SIGKILL: the process dies at once, whatever it was doing.
    pub fn kill(mut self) {
        self.child.kill().expect("SIGKILL");
        self.child.wait().expect("reaped");
    }

    /// Sends SIGTERM and waits up to `timeout` for the exit; None if it did not exit.
    pub fn terminate(mut self, timeout: Duration) -> (Option<ExitStatus>, Duration, String) {
        let pid = self.child.id().to_string();
        let sent = Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .expect("kill runs");
        assert!(sent.success(), "cannot send SIGTERM to {pid}");
        let start = Instant::now();
        loop {
            if let Some(status) = self.child.try_wait().expect("child status") {
                return (Some(status), start.elapsed(), self.log());
            }
            if start.elapsed() > timeout {
                let log = self.log();
                let _ = self.child.kill();
                let _ = self.child.wait();
                return (None, start.elapsed(), log);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Sends a request; panics when the server cannot be reached.
    pub fn request(
        &self,
        method: &str,
        path: &str,
        headers: &[(&str, &str)],
        body: &[u8],
    ) -> Response {
        self.try_request(method, path, headers, body)
            .unwrap_or_else(|e| panic!("{method} {path}: {e}\n{}", self.log()))
    }

    /// Sends a request; Err when the connection fails.
    pub fn try_request(
        &self,
        method: &str,
        path: &str,
        headers: &[(&str, &str)],
        body: &[u8],
    ) -> std::io::Result<Response> {
        http(self.port, method, path, headers, body)
    }

    /// GET, expecting JSON.
    pub fn get_json(&self, path: &str) -> Value {
        let r = self.request("GET", path, &[], &[]);
        assert_eq!(r.status, 200, "GET {path}: {}", r.text());
        r.json()
    }

    /// POST a JSON body.
    pub fn post_json(&self, path: &str, body: &Value) -> Response {
        let headers = [("content-type", "application/json")];
        self.request("POST", path, &headers, body.to_string().as_bytes())
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// A collected response.
#[derive(Debug)]
pub struct Response {
    /// Status code.
    pub status: u16,
    /// Header names in lower case.
    pub headers: Vec<(String, String)>,
    /// Body (chunked transfer decoded).
    pub body: Vec<u8>,
}

impl Response {
    /// The body as JSON.
    pub fn json(&self) -> Value {
        serde_json::from_slice(&self.body)
            .unwrap_or_else(|e| panic!("not JSON ({e}): {}", self.text()))
    }

    /// The body as text.
    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

fn http(
    port: u16,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &[u8],
) -> std::io::Result<Response> {
    let mut stream = TcpStream::connect(("127.0.0.1", port))?;
    stream.set_read_timeout(Some(Duration::from_secs(120)))?;
    let mut head = format!(
        "{method} {path} HTTP/1.1\r\nhost: 127.0.0.1:{port}\r\nconnection: close\r\ncontent-length: {}\r\n",
        body.len()
    );
    for (k, v) in headers {
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    head.push_str("\r\n");
    stream.write_all(head.as_bytes())?;
    stream.write_all(body)?;
    let mut raw = Vec::new();
    stream.read_to_end(&mut raw)?;
    parse_response(&raw)
}

fn parse_response(raw: &[u8]) -> std::io::Result<Response> {
    let bad = |what: &str| std::io::Error::new(std::io::ErrorKind::InvalidData, what.to_owned());
    let end = raw
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .ok_or_else(|| bad("no end of headers"))?;
    let head = std::str::from_utf8(&raw[..end]).map_err(|_| bad("headers not UTF-8"))?;
    let mut lines = head.split("\r\n");
    let status = lines
        .next()
        .and_then(|l| l.split(' ').nth(1))
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| bad("no status line"))?;
    let headers: Vec<(String, String)> = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_owned()))
        .collect();
    let rest = &raw[end + 4..];
    let chunked = headers
        .iter()
        .any(|(k, v)| k == "transfer-encoding" && v.contains("chunked"));
    let body = if chunked {
        dechunk(rest).ok_or_else(|| bad("bad chunks"))?
    } else {
        rest.to_vec()
    };
    Ok(Response {
        status,
        headers,
        body,
    })
}

fn dechunk(mut data: &[u8]) -> Option<Vec<u8>> {
    let mut out = Vec::new();
    loop {
        let line_end = data.windows(2).position(|w| w == b"\r\n")?;
        let size_text = std::str::from_utf8(&data[..line_end]).ok()?;
        let size = usize::from_str_radix(size_text.split(';').next()?.trim(), 16).ok()?;
        data = &data[line_end + 2..];
        if size == 0 {
            return Some(out);
        }
        out.extend_from_slice(data.get(..size)?);
        data = data.get(size + 2..)?;
    }
}

/// A multipart/form-data body: `(name, file name, bytes)` parts; returns the content type
/// and the body.
pub fn multipart(parts: &[(&str, Option<&str>, &[u8])]) -> (String, Vec<u8>) {
    let boundary = "aortagen-test-boundary-7d1f";
    let mut body = Vec::new();
    for (name, file, bytes) in parts {
        body.extend_from_slice(format!("--{boundary}\r\n").as_bytes());
        let disposition = match file {
            Some(f) => format!("form-data; name=\"{name}\"; filename=\"{f}\""),
            None => format!("form-data; name=\"{name}\""),
        };
        body.extend_from_slice(format!("content-disposition: {disposition}\r\n\r\n").as_bytes());
        body.extend_from_slice(bytes);
        body.extend_from_slice(b"\r\n");
    }
    body.extend_from_slice(format!("--{boundary}--\r\n").as_bytes());
    (format!("multipart/form-data; boundary={boundary}"), body)
}

/// An ellipsoid with semi-axes `axes` as OBJ text (a UV sphere, outward triangles).
pub fn ellipsoid_obj(axes: [f64; 3], rings: usize, segments: usize) -> Vec<u8> {
    use std::f64::consts::PI;
    use std::fmt::Write as _;
    let mut obj = String::new();
    let vertex = |obj: &mut String, p: [f64; 3]| {
        writeln!(
            obj,
            "v {} {} {}",
            p[0] * axes[0],
            p[1] * axes[1],
            p[2] * axes[2]
        )
        .unwrap()
    };
    vertex(&mut obj, [0.0, 0.0, 1.0]);
    for i in 1..rings {
        let theta = PI * i as f64 / rings as f64;
        for j in 0..segments {
            let phi = 2.0 * PI * j as f64 / segments as f64;
            vertex(
                &mut obj,
                [
                    theta.sin() * phi.cos(),
                    theta.sin() * phi.sin(),
                    theta.cos(),
                ],
            );
        }
    }
    vertex(&mut obj, [0.0, 0.0, -1.0]);
    let ring = |i: usize, j: usize| 2 + (i - 1) * segments + j % segments;
    let south = 2 + (rings - 1) * segments;
    for j in 0..segments {
        writeln!(obj, "f 1 {} {}", ring(1, j), ring(1, j + 1)).unwrap();
        writeln!(
            obj,
            "f {} {} {south}",
            ring(rings - 1, j + 1),
            ring(rings - 1, j)
        )
        .unwrap();
    }
    for i in 1..rings - 1 {
        for j in 0..segments {
            let (a, b) = (ring(i, j), ring(i, j + 1));
            let (c, d) = (ring(i + 1, j), ring(i + 1, j + 1));
            writeln!(obj, "f {a} {c} {d}").unwrap();
            writeln!(obj, "f {a} {d} {b}").unwrap();
        }
    }
    obj.into_bytes()
}

/// Opens the database directly (the server must be stopped) and runs `f` on it.
pub fn with_database<T>(path: &Path, f: impl AsyncFnOnce(&aortagen::db::Pool) -> T) -> T {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    runtime.block_on(async {
        let url = format!("sqlite://{}", path.display());
        let pool = aortagen::db::open(&url, 2, &Default::default())
            .await
            .expect("database opens");
        let out = f(&pool).await;
        pool.close().await;
        out
    })
}
