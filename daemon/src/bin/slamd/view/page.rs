//! The page: one self-contained HTML file (no CDN, nothing fetched at run
//! time) served over plain HTTP. It connects back to the viewer's Foxglove
//! WebSocket server and draws the map from its JSON channels.

use std::io::{self, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::Duration;

/// The page, with `__WS_PORT__` where the WebSocket port goes.
const PAGE: &str = include_str!("page.html");

/// Connections served at once; more are closed at once.
const MAX_CONNECTIONS: usize = 32;

/// How long a client may take to send its request or read the answer.
const CLIENT_TIMEOUT: Duration = Duration::from_secs(5);

/// The longest request head read.
const MAX_HEAD: usize = 8192;

/// Serves the page on `host:port` (0: any free port) from a thread of its
/// own, pointing it at the WebSocket server on `ws_port`; returns the port
/// bound.
pub fn serve(host: &str, port: u16, ws_port: u16) -> io::Result<u16> {
    let listener = TcpListener::bind((host, port))?;
    let bound = listener.local_addr()?.port();
    let page: Arc<str> = PAGE.replace("__WS_PORT__", &ws_port.to_string()).into();
    let open = Arc::new(AtomicUsize::new(0));
    thread::Builder::new().name("page".into()).spawn(move || {
        for stream in listener.incoming().flatten() {
            if open.fetch_add(1, Ordering::AcqRel) >= MAX_CONNECTIONS {
                open.fetch_sub(1, Ordering::AcqRel);
                continue;
            }
            let (page, open) = (page.clone(), open.clone());
            let spawned = thread::Builder::new().name("page-client".into()).spawn(move || {
                if let Err(e) = answer(stream, &page) {
                    tracing::debug!(error = %e, "A page client went away.");
                }
                open.fetch_sub(1, Ordering::AcqRel);
            });
            if spawned.is_err() {
                tracing::warn!("Cannot start a thread for a page client.");
            }
        }
    })?;
    Ok(bound)
}

/// Reads one request head and answers it: the page for `GET /`, 404 for
/// any other path, 400 for anything that is not a GET.
fn answer(mut stream: TcpStream, page: &str) -> io::Result<()> {
    stream.set_read_timeout(Some(CLIENT_TIMEOUT))?;
    stream.set_write_timeout(Some(CLIENT_TIMEOUT))?;
    let head = read_head(&mut stream)?;
    let (status, kind, body) = route(&head, page);
    write!(
        stream,
        "HTTP/1.1 {status}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    )?;
    stream.write_all(body.as_bytes())?;
    stream.flush()
}

/// The bytes up to the blank line that ends a request head (or
/// [`MAX_HEAD`], or the end of the stream).
fn read_head(stream: &mut impl Read) -> io::Result<Vec<u8>> {
    let mut head = Vec::new();
    let mut buf = [0u8; 1024];
    while head.len() < MAX_HEAD && !head.windows(4).any(|w| w == b"\r\n\r\n") {
        let n = stream.read(&mut buf)?;
        if n == 0 {
            break;
        }
        head.extend_from_slice(&buf[..n]);
    }
    Ok(head)
}

/// Status line, content type and body for a request head.
fn route<'p>(head: &[u8], page: &'p str) -> (&'static str, &'static str, &'p str) {
    let line = head
        .split(|&b| b == b'\r' || b == b'\n')
        .next()
        .unwrap_or_default();
    let mut words = line.split(|&b| b == b' ');
    match (words.next(), words.next()) {
        (Some(b"GET"), Some(b"/" | b"/index.html")) => ("200 OK", "text/html; charset=utf-8", page),
        (Some(b"GET"), Some(_)) => ("404 Not Found", "text/plain", "not found\n"),
        _ => ("400 Bad Request", "text/plain", "bad request\n"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_answers_get_of_the_root_only() {
        assert_eq!(route(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n", "P").2, "P");
        assert_eq!(route(b"GET /index.html HTTP/1.0\r\n\r\n", "P").0, "200 OK");
        assert_eq!(route(b"GET /other HTTP/1.1\r\n\r\n", "P").0, "404 Not Found");
        assert_eq!(route(b"\x00\xff garbage", "P").0, "400 Bad Request");
        assert_eq!(route(b"", "P").0, "400 Bad Request");
    }

    #[test]
    fn a_served_page_points_at_the_websocket_port() {
        let port = serve("127.0.0.1", 0, 4321).unwrap();
        let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
        s.write_all(b"GET / HTTP/1.1\r\nHost: localhost\r\n\r\n").unwrap();
        let mut answer = String::new();
        s.read_to_string(&mut answer).unwrap();
        assert!(answer.starts_with("HTTP/1.1 200 OK\r\n"), "{answer:.80}");
        assert!(answer.contains("4321") && !answer.contains("__WS_PORT__"));
        assert!(
            !answer.contains("http://") && !answer.contains("https://"),
            "the page fetches nothing"
        );
    }
}
