//! Errors as text for a person: an error's message followed by those of its sources.
//!
//! The project's error types keep what went wrong underneath (an I/O error, a zlib stream's
//! complaint, a DICOM parser's) as their `source()`, not in their own message; whoever shows
//! an error to a user shows the whole chain with [`chain`] (the CLI's anyhow does the same with
//! `{:#}`).

/// The message of an error and of its sources, on one line, separated by ": ". A source whose
/// message the text already holds is not repeated.
pub fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cur = e.source();
    while let Some(inner) = cur {
        let m = inner.to_string();
        if !s.contains(&m) {
            s.push_str(": ");
            s.push_str(&m);
        }
        cur = inner.source();
    }
    s
}

#[cfg(test)]
mod tests {
    #[derive(Debug, thiserror::Error)]
    #[error("outer.nii.gz: cannot read at byte 3")]
    struct Outer(#[source] std::io::Error);

    #[test]
    fn the_chain_names_every_source_once() {
        let e = Outer(std::io::Error::other("disk on fire"));
        assert_eq!(
            super::chain(&e),
            "outer.nii.gz: cannot read at byte 3: disk on fire"
        );
        // A source whose words the outer message already holds is not said twice.
        #[derive(Debug, thiserror::Error)]
        #[error("a: disk on fire")]
        struct Repeats(#[source] std::io::Error);
        let e = Repeats(std::io::Error::other("disk on fire"));
        assert_eq!(super::chain(&e), "a: disk on fire");
    }
}
