//! Key expressions: the one module that turns KPL names into zenoh keys (docs/streams.md, "Key
//! expressions", is the reference).
//!
//! A stream between hosts is published on `kpl/<deployment>/<spec>/<producer>` (its default
//! output) or `kpl/<deployment>/<spec>/<producer>/<port>` (a named output such as a link's
//! `changes`). The deployment's name comes first, so deployments of one spec never exchange a
//! sample. Every name is one key chunk, escaped with [`escape_chunk`] so that no name can contain
//! a separator (`/`), a wildcard (`*`, `$`), a reserved character (`#`, `?`) or start a verbatim
//! chunk (`@`).
//!
//! Beside the data, liveliness tokens say who is there, and one queryable keeps each stream's end:
//! - `<stream>/@subscriber/<host>`: a host subscribed to the stream (a publisher waits for every
//!   consuming host, and counts what it publishes while one is away);
//! - `<stream>/@publisher/<host>`: the producing host is there (a subscriber notices when it goes
//!   away and comes back);
//! - `<stream>/@end`: the producing host answers queries with the end of the stream once it has
//!   ended, for a host that subscribes late or was away when the end went out;
//! - `<stream>/@ack/<host>`: a consuming host acknowledges, with its envelope, how far it has
//!   taken the stream (the producer's credit) and that it has the end;
//! - `kpl/<deployment>/<spec>/@host/<host>`: the host runs;
//! - `kpl/<deployment>/<spec>/@hello/<host>`: the host says, with its envelope, which process runs
//!   it (two processes of one host at once are a clash).
//!
//! `@` chunks are verbatim in zenoh: no wildcard matches them, so an outside program subscribing
//! to `kpl/<deployment>/<spec>/**` sees the data of every stream and none of the tokens.

use kpl_runtime::transport::StreamKey;

/// The first chunk of every key KPL publishes on.
pub const ROOT: &str = "kpl";

/// The keys of a deployment of a spec: `kpl/<deployment>/<spec>`.
pub fn deployment(deployment: &str, spec: &str) -> String {
    format!("{ROOT}/{}/{}", escape_chunk(deployment), escape_chunk(spec))
}

/// The key expression a stream is published on.
pub fn stream(key: &StreamKey) -> String {
    let mut out = format!("{}/{}", deployment(&key.deployment, &key.spec), escape_chunk(&key.producer));
    if let Some(port) = &key.port {
        out.push('/');
        out.push_str(&escape_chunk(port));
    }
    out
}

/// The liveliness token a host declares when it subscribes to a stream.
pub fn subscriber_token(key: &StreamKey, host: &str) -> String {
    format!("{}/@subscriber/{}", stream(key), escape_chunk(host))
}

/// Matches the subscriber tokens of every host of a stream.
pub fn subscriber_tokens(key: &StreamKey) -> String {
    format!("{}/@subscriber/*", stream(key))
}

/// The liveliness token the producing host declares while it publishes a stream.
pub fn publisher_token(key: &StreamKey, host: &str) -> String {
    format!("{}/@publisher/{}", stream(key), escape_chunk(host))
}

/// Matches the publisher tokens of a stream.
pub fn publisher_tokens(key: &StreamKey) -> String {
    format!("{}/@publisher/*", stream(key))
}

/// Where a consuming host acknowledges what it has of a stream (credit for the producer, and
/// the end once it has it).
pub fn ack(key: &StreamKey, host: &str) -> String {
    format!("{}/@ack/{}", stream(key), escape_chunk(host))
}

/// Matches the acknowledgments of every consuming host of a stream.
pub fn acks(key: &StreamKey) -> String {
    format!("{}/@ack/*", stream(key))
}

/// Where a host of a deployment says, with its envelope, that it runs (and which process it is).
pub fn hello(deployment_name: &str, spec: &str, host: &str) -> String {
    format!("{}/@hello/{}", deployment(deployment_name, spec), escape_chunk(host))
}

/// Matches the hellos of every host of a deployment.
pub fn hellos(deployment_name: &str, spec: &str) -> String {
    format!("{}/@hello/*", deployment(deployment_name, spec))
}

/// Where the producing host answers with the end of a stream.
pub fn end(key: &StreamKey) -> String {
    format!("{}/@end", stream(key))
}

/// The liveliness token of a running host.
pub fn host_token(deployment_name: &str, spec: &str, host: &str) -> String {
    format!("{}/@host/{}", deployment(deployment_name, spec), escape_chunk(host))
}

/// Matches the tokens of every running host of a deployment.
pub fn host_tokens(deployment_name: &str, spec: &str) -> String {
    format!("{}/@host/*", deployment(deployment_name, spec))
}

/// The last chunk of a token's key, unescaped: the host that declared it.
pub fn token_host(token_key: &str) -> Option<String> {
    unescape_chunk(token_key.rsplit('/').next()?)
}

/// Escapes a name into one key chunk: ASCII letters, digits, `_`, `-` and `.` stay, every other
/// byte of the UTF-8 text becomes `%XX` (upper-case hex), and the empty name becomes `%` (a lone
/// `%` never results from a non-empty name). The result is never empty, never contains `/`, `*`,
/// `$`, `#`, `?` or `@`, and different names give different chunks.
pub fn escape_chunk(name: &str) -> String {
    if name.is_empty() {
        return "%".to_string();
    }
    let mut out = String::with_capacity(name.len());
    for byte in name.bytes() {
        if byte.is_ascii_alphanumeric() || matches!(byte, b'_' | b'-' | b'.') {
            out.push(char::from(byte));
        } else {
            out.push('%');
            out.push(char::from(HEX[usize::from(byte >> 4)]));
            out.push(char::from(HEX[usize::from(byte & 0x0f)]));
        }
    }
    out
}

const HEX: &[u8; 16] = b"0123456789ABCDEF";

/// The name an [`escape_chunk`] result stands for; `None` if `chunk` is not one.
pub fn unescape_chunk(chunk: &str) -> Option<String> {
    match chunk {
        "%" => return Some(String::new()),
        "" => return None,
        _ => {}
    }
    let bytes = chunk.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'%' => {
                let hi = hex_value(*bytes.get(i + 1)?)?;
                let lo = hex_value(*bytes.get(i + 2)?)?;
                let byte = (hi << 4) | lo;
                // Only bytes that escaping would have escaped: one name, one chunk.
                if byte.is_ascii_alphanumeric() || matches!(byte, b'_' | b'-' | b'.') {
                    return None;
                }
                out.push(byte);
                i += 3;
            }
            b if b.is_ascii_alphanumeric() || matches!(b, b'_' | b'-' | b'.') => {
                out.push(b);
                i += 1;
            }
            _ => return None,
        }
    }
    String::from_utf8(out).ok()
}

fn hex_value(digit: u8) -> Option<u8> {
    match digit {
        b'0'..=b'9' => Some(digit - b'0'),
        b'A'..=b'F' => Some(digit - b'A' + 10),
        _ => None,
    }
}

/// Why a key given to `zenoh.subscribe` or `zenoh.publish` cannot be used.
pub fn check_user_key(key: &str, wildcards_allowed: bool) -> Result<(), String> {
    let parsed = zenoh::key_expr::KeyExpr::try_from(key.to_string())
        .map_err(|e| format!("`{key}` is not a zenoh key expression: {e}"))?;
    if !wildcards_allowed && parsed.is_wild() {
        return Err(format!("`{key}` has wildcards; publish on one key (`a/b`, not `a/*` or `a/**`)"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn key(spec: &str, producer: &str, port: Option<&str>) -> StreamKey {
        StreamKey {
            deployment: "trial".into(),
            spec: spec.into(),
            producer: producer.into(),
            port: port.map(String::from),
        }
    }

    #[test]
    fn keys_of_streams() {
        assert_eq!(stream(&key("bridge", "tracker", None)), "kpl/trial/bridge/tracker");
        assert_eq!(
            stream(&key("bridge", "vision_world", Some("changes"))),
            "kpl/trial/bridge/vision_world/changes"
        );
        assert_eq!(stream(&key("my spec*", "p", None)), "kpl/trial/my%20spec%2A/p");
        let other = StreamKey { deployment: "site-3/b".into(), ..key("s", "p", None) };
        assert_eq!(stream(&other), "kpl/site-3%2Fb/s/p");
        assert_eq!(subscriber_token(&key("s", "p", None), "ground"), "kpl/trial/s/p/@subscriber/ground");
        assert_eq!(ack(&key("s", "p", Some("o")), "g"), "kpl/trial/s/p/o/@ack/g");
        assert_eq!(end(&key("s", "p", None)), "kpl/trial/s/p/@end");
        assert_eq!(host_token("trial", "s", "uav"), "kpl/trial/s/@host/uav");
        assert_eq!(ack(&key("s", "p", None), "g"), "kpl/trial/s/p/@ack/g");
        assert_eq!(hello("trial", "s", "uav"), "kpl/trial/s/@hello/uav");
        assert_eq!(token_host("kpl/trial/s/p/@subscriber/gr%C3%B6und").as_deref(), Some("gröund"));
    }

    #[test]
    fn tokens_are_out_of_reach_of_wildcards() {
        let all = zenoh::key_expr::KeyExpr::try_from("kpl/trial/s/**").unwrap();
        for token in [
            subscriber_token(&key("s", "p", None), "g"),
            publisher_token(&key("s", "p", Some("o")), "g"),
            end(&key("s", "p", None)),
            host_token("trial", "s", "g"),
            ack(&key("s", "p", None), "g"),
            hello("trial", "s", "g"),
        ] {
            let token = zenoh::key_expr::KeyExpr::try_from(token).unwrap();
            assert!(!all.intersects(&token), "{token}");
        }
        assert!(all.intersects(&zenoh::key_expr::KeyExpr::try_from(stream(&key("s", "p", None))).unwrap()));
    }

    #[test]
    fn escaping_is_injective_and_reversible_on_awkward_names() {
        let names = ["", "%", "a/b", "**", "$*", "@x", "#?", "a b", "ü", "%25", ".", "..", "A-z_0.9"];
        let mut chunks: Vec<String> = names.iter().map(|n| escape_chunk(n)).collect();
        for (name, chunk) in names.iter().zip(&chunks) {
            assert_eq!(unescape_chunk(chunk).as_deref(), Some(*name), "{chunk}");
            zenoh::key_expr::KeyExpr::try_from(format!("kpl/{chunk}/x")).unwrap();
        }
        chunks.sort();
        chunks.dedup();
        assert_eq!(chunks.len(), names.len());
    }

    #[test]
    fn non_canonical_chunks_are_refused() {
        for chunk in ["%41", "%2a", "%2", "a/b", "", "%%"] {
            assert_eq!(unescape_chunk(chunk), None, "{chunk}");
        }
    }

    #[test]
    fn user_keys() {
        assert!(check_user_key("sensors/temp", false).is_ok());
        assert!(check_user_key("sensors/**", true).is_ok());
        assert!(check_user_key("sensors/**", false).unwrap_err().contains("wildcards"));
        assert!(check_user_key("a//b", true).unwrap_err().contains("not a zenoh key expression"));
        assert!(check_user_key("", true).is_err());
    }

    proptest::proptest! {
        #[test]
        fn any_name_escapes_to_a_valid_chunk(name in "\\PC{0,24}", other in "\\PC{0,24}") {
            let chunk = escape_chunk(&name);
            proptest::prop_assert_eq!(unescape_chunk(&chunk), Some(name.clone()));
            let ke = format!("kpl/{chunk}/p");
            proptest::prop_assert!(zenoh::key_expr::KeyExpr::try_from(ke.clone()).is_ok(), "{}", ke);
            if name != other {
                proptest::prop_assert_ne!(chunk, escape_chunk(&other));
            }
        }
    }
}
