use super::*;

const CT: &str = "multipart/related; type=\"application/dicom\"; boundary=d7d1f0a6-a8c5";

/// A body as Orthanc writes it (headers of each part, CRLF, content, CRLF, boundary).
fn body(parts: &[&[u8]]) -> Vec<u8> {
    let mut b = Vec::new();
    for p in parts {
        b.extend_from_slice(b"--d7d1f0a6-a8c5\r\nContent-Type: application/dicom; transfer-syntax=1.2.840.10008.1.2.1\r\n");
        b.extend_from_slice(
            format!("Content-Length: {}\r\nMIME-Version: 1.0\r\n\r\n", p.len()).as_bytes(),
        );
        b.extend_from_slice(p);
        b.extend_from_slice(b"\r\n");
    }
    b.extend_from_slice(b"--d7d1f0a6-a8c5--\r\n");
    b
}

fn parse_in_chunks(ct: &str, data: &[u8], chunk: usize) -> Result<Vec<Part>, DicomWebError> {
    let mut p = MultipartParser::new(Some(ct), "test", MultipartLimits::default())?;
    let mut parts = Vec::new();
    let mut push = |part: Part| {
        parts.push(part);
        Ok(())
    };
    for c in data.chunks(chunk.max(1)) {
        p.feed(c, &mut push)?;
    }
    p.finish(&mut push)?;
    Ok(parts)
}

#[test]
fn parts_come_out_whole_whatever_the_chunking() {
    // Content that holds CR, LF, dashes and a near-boundary.
    let a: Vec<u8> = b"DICM\r\n--d7d1f0a6-a8c\r\n--\r\n\r\n".repeat(50);
    let b: Vec<u8> = (0..=255u8).cycle().take(5000).collect();
    let data = body(&[&a, &b, b""]);
    for chunk in [1, 2, 3, 7, 17, 64, 1000, data.len()] {
        let parts = parse_in_chunks(CT, &data, chunk).unwrap();
        assert_eq!(parts.len(), 3, "chunk {chunk}");
        assert_eq!(parts[0].bytes, a);
        assert_eq!(parts[1].bytes, b);
        assert!(parts[2].bytes.is_empty());
        assert_eq!(parts[1].index, 2);
        assert_eq!(
            parts[0].transfer_syntax.as_deref(),
            Some("1.2.840.10008.1.2.1")
        );
    }
}

#[test]
fn preamble_quoted_boundary_padding_and_epilogue() {
    let ct = "Multipart/Related; boundary=\"a b:c\"; type=\"application/dicom\"";
    let data = b"preamble text\r\n--a b:c  \t\r\n\r\nXYZ\r\n--a b:c--\r\nepilogue".to_vec();
    let parts = parse_in_chunks(ct, &data, 3).unwrap();
    assert_eq!(parts.len(), 1);
    assert_eq!(parts[0].bytes, b"XYZ");
    assert_eq!(parts[0].content_type, None);
}

#[test]
fn single_application_dicom_body() {
    let parts = parse_in_chunks(
        "application/dicom; transfer-syntax=1.2.840.10008.1.2.5",
        b"DICMxyz",
        2,
    )
    .unwrap();
    assert_eq!(parts[0].bytes, b"DICMxyz");
    assert_eq!(
        parts[0].transfer_syntax.as_deref(),
        Some("1.2.840.10008.1.2.5")
    );
}

#[test]
fn content_types_that_are_refused() {
    for ct in [
        None,
        Some("application/json"),
        Some("multipart/related; type=\"application/dicom\""),
        Some("multipart/related; type=\"image/jpeg\"; boundary=x"),
        Some("multipart/related; boundary=\"\""),
        Some("multipart/related; boundary=a\u{7}b"),
    ] {
        let e = MultipartParser::new(ct, "instance 1", MultipartLimits::default());
        let e = e.err().unwrap().to_string();
        assert!(e.starts_with("instance 1: multipart body: "), "{ct:?}: {e}");
    }
}

#[test]
fn a_body_cut_anywhere_is_an_error_naming_the_part() {
    let a = vec![7u8; 300];
    let data = body(&[&a, &a]);
    let closing = data.len() - b"--d7d1f0a6-a8c5--\r\n".len() + b"--d7d1f0a6-a8c5--".len();
    for cut in 0..closing {
        let r = parse_in_chunks(CT, &data[..cut], 13);
        let e = r
            .err()
            .unwrap_or_else(|| panic!("cut at {cut} passed"))
            .to_string();
        assert!(e.contains("test: multipart body"), "{cut}: {e}");
    }
    let e = parse_in_chunks(CT, &data[..200], 50)
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("part 1 was cut short") && e.contains("of the 300 it declares"),
        "{e}"
    );
    let first_end = data.windows(6).position(|w| w == b"\r\n--d7").unwrap();
    let e = parse_in_chunks(CT, &data[..first_end + 400], 50)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("part 2 was cut short"), "{e}");
    assert!(parse_in_chunks(CT, &data[..closing], 50).is_ok());
}

#[test]
fn caps_hold() {
    let limits = MultipartLimits {
        max_part_bytes: 100,
        max_parts: 2,
    };
    let run = |data: &[u8]| {
        let mut p = MultipartParser::new(Some(CT), "t", limits).unwrap();
        let mut n = 0;
        let mut count = |_: Part| {
            n += 1;
            Ok(())
        };
        for c in data.chunks(10) {
            p.feed(c, &mut count)?;
        }
        p.finish(&mut count)
    };
    let e = run(&body(&[&[1u8; 101]])).unwrap_err().to_string();
    assert!(e.contains("part 1") && e.contains("limit of 100"), "{e}");
    // A part that declares more than the cap is refused before its bytes are read.
    let lie = b"--d7d1f0a6-a8c5\r\nContent-Length: 999999999999\r\n\r\nxx";
    assert!(run(lie).unwrap_err().to_string().contains("limit of 100"));
    // A part without a closing boundary cannot grow past the cap either.
    let mut endless = b"--d7d1f0a6-a8c5\r\n\r\n".to_vec();
    endless.extend(std::iter::repeat_n(0u8, 10_000));
    assert!(
        run(&endless)
            .unwrap_err()
            .to_string()
            .contains("limit of 100")
    );
    let e = run(&body(&[b"a", b"b", b"c"])).unwrap_err().to_string();
    assert!(e.contains("more than 2 parts"), "{e}");
    let e = run(&vec![b'x'; MAX_PREAMBLE + 100])
        .unwrap_err()
        .to_string();
    assert!(e.contains("no boundary line"), "{e}");
    let mut headers = b"--d7d1f0a6-a8c5\r\n".to_vec();
    headers.extend(b"X: y\r\n".repeat(5000));
    assert!(
        run(&headers)
            .unwrap_err()
            .to_string()
            .contains("headers longer")
    );
    assert!(
        run(b"--d7d1f0a6-a8c5xx")
            .unwrap_err()
            .to_string()
            .contains("CRLF")
    );
}

#[test]
fn random_bodies_never_panic() {
    // A fixed xorshift stream: bodies built from boundary fragments and noise.
    let mut s = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    let atoms: [&[u8]; 7] = [
        b"--d7d1f0a6-a8c5",
        b"\r\n",
        b"--",
        b"Content-Length: 3\r\n",
        b"\r\n\r\n",
        b"xyz",
        b"\r",
    ];
    for _ in 0..3000 {
        let mut data = Vec::new();
        for _ in 0..(next() % 20) {
            if next() % 4 == 0 {
                data.push(next() as u8);
            } else {
                data.extend_from_slice(atoms[(next() % atoms.len() as u64) as usize]);
            }
        }
        let chunk = (next() % 8 + 1) as usize;
        let _ = parse_in_chunks(CT, &data, chunk);
    }
}

#[test]
fn content_type_parameters() {
    let (m, p) = parse_content_type(
        "Multipart/Related; TYPE=\"application/dicom\"; boundary=\"x;y\\\"z\"; a",
    );
    assert_eq!(m, "multipart/related");
    assert_eq!(param(&p, "type"), Some("application/dicom"));
    assert_eq!(param(&p, "boundary"), Some("x;y\"z"));
}
