//! URL strings, the one place for them: percent-encoding (links, DICOMweb queries), decoding
//! of `a=1&b=x%20y` strings (the page's query, a link's fragment) into (key, value) pairs, and
//! the host part of a URL for messages. Strings only: no requests here.

/// Percent-encodes everything but the unreserved characters (RFC 3986: letters, digits,
/// `-._~`) and the bytes of `keep`.
pub fn percent_encode(s: &str, keep: &[u8]) -> String {
    let mut out = String::with_capacity(s.len());
    for b in s.bytes() {
        if b.is_ascii_alphanumeric() || b"-._~".contains(&b) || keep.contains(&b) {
            out.push(char::from(b));
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

/// Percent-encodes a link's value: everything but unreserved characters and a few that are
/// safe and readable inside a fragment or query value (`/`, `:`, `@`, `,`), so a URL value
/// stays legible.
pub fn encode(s: &str) -> String {
    percent_encode(s, b"/:@,")
}

/// The host part of an absolute URL ("example.org:8080"); `None` without a scheme.
pub fn host_part(url: &str) -> Option<&str> {
    let rest = url.split_once("://")?.1;
    rest.split(['/', '?', '#']).next()
}

/// The host part of a URL ("example.org:8080"), or the URL itself when it has none.
pub fn host_of(url: &str) -> String {
    host_part(url).unwrap_or(url).to_owned()
}

/// Decodes `%XX` escapes and `+` (a space, as forms and `URLSearchParams` write it). Malformed
/// escapes are kept as they are; invalid UTF-8 becomes U+FFFD.
pub fn decode(s: &str) -> String {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'+' => {
                out.push(b' ');
                i += 1;
            }
            b'%' if i + 2 < bytes.len() => {
                let hex = |c: u8| (c as char).to_digit(16);
                match (hex(bytes[i + 1]), hex(bytes[i + 2])) {
                    (Some(h), Some(l)) => {
                        out.push((h * 16 + l) as u8);
                        i += 3;
                    }
                    _ => {
                        out.push(b'%');
                        i += 1;
                    }
                }
            }
            c => {
                out.push(c);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// `a=1&b=x%20y&c` as decoded (key, value) pairs in order (repeated keys kept); a leading `?`
/// or `#` is skipped.
pub fn parse_params(s: &str) -> Vec<(String, String)> {
    s.trim_start_matches(['?', '#'])
        .split('&')
        .filter(|kv| !kv.is_empty())
        .map(|kv| {
            let (k, v) = kv.split_once('=').unwrap_or((kv, ""));
            (decode(k), decode(v))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn query_values_are_percent_decoded() {
        let p = parse_params(
            "?url=https%3A%2F%2Fx.org%2Fa%20b.nii.gz&url=c+d.raw&flag&bad=%4&u=%E2%9C%93",
        );
        assert_eq!(
            p,
            vec![
                ("url".into(), "https://x.org/a b.nii.gz".into()),
                ("url".into(), "c d.raw".into()),
                ("flag".into(), String::new()),
                ("bad".into(), "%4".into()),
                ("u".into(), "✓".into()),
            ]
        );
        assert_eq!(decode(&encode("a b/ü?&=#%+")), "a b/ü?&=#%+");
        assert_eq!(encode("a b/c:d@e,f*"), "a%20b/c:d@e,f%2A");
        assert_eq!(percent_encode("Doe^J*", b"*"), "Doe%5EJ*");
        assert_eq!(host_of("https://h.org:8443/x?y"), "h.org:8443");
        assert_eq!(host_of("https://h.org#frag"), "h.org");
        assert_eq!(host_of("/relative/path"), "/relative/path");
        assert_eq!(host_part("/relative/path"), None);
    }
}
