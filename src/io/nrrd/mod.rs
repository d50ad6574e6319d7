//! NRRD reader (teem's format, as Slicer writes it): attached (.nrrd) and detached (.nhdr plus a
//! data file given beside it) data; raw, gzip and ascii encodings; either endianness; space
//! directions and space origin in any of the anatomical spaces, converted to LPS. Non-spatial
//! axes (a DWI's gradient list, a time axis) are reduced to their first element, with a warning.

use glam::DVec3;

use super::geometry::checked_grid;
use super::input::Data;
use super::raw::{self, Endian, SampleLayout};
use super::{HeaderInput, Limits, LoadError};
use crate::volume::Volume;

mod header;

use header::{
    MAX_HEADER_BYTES, get, parse_vector, sample_type, space_to_lps, split_header, vector_tokens,
};

/// Reads an attached .nrrd or a detached .nhdr (its data file is looked up among `companions`).
pub(crate) fn read(input: HeaderInput<'_>) -> Result<Volume, LoadError> {
    let name = input.file.name.as_str();
    // A file read on demand is parsed from its first 64 KiB, or up to the header cap when the
    // header is longer.
    let (fields, data_start) = {
        let on_demand = input.file.is_on_demand();
        let mut parsed = split_header(
            name,
            &input
                .file
                .prefix(if on_demand { 64 << 10 } else { usize::MAX })?,
        );
        // The prefix's end may cut a line: its parse counts only if the header ended before it.
        let whole = !on_demand || input.file.len() <= 64 << 10;
        if !whole && !matches!(parsed, Ok((_, Some(start))) if start < 64 << 10) {
            parsed = split_header(name, &input.file.prefix(MAX_HEADER_BYTES + 1)?);
        }
        parsed?
    };
    let mut warnings = Vec::new();
    let need = |names: &[&str]| {
        get(&fields, names)
            .ok_or_else(|| LoadError::header(name, names[0], "missing (a required NRRD field)"))
    };

    let ty = sample_type(name, need(&["type"])?)?;
    let dimension: usize = LoadError::parse_field(
        name,
        "dimension",
        need(&["dimension"])?,
        "not a positive integer",
    )?;
    if !(1..=16).contains(&dimension) {
        return Err(LoadError::header(
            name,
            "dimension",
            format!("is {dimension}; expected 1 to 16"),
        ));
    }
    let sizes: Vec<u64> = need(&["sizes"])?
        .split_whitespace()
        .map(|s| {
            s.parse::<u64>()
                .map_err(|_| LoadError::header(name, "sizes", format!("\"{s}\" is not a size")))
        })
        .collect::<Result<_, _>>()?;
    if sizes.len() != dimension || sizes.contains(&0) {
        return Err(LoadError::header(
            name,
            "sizes",
            format!("{sizes:?} does not give {dimension} non-zero sizes"),
        ));
    }

    // Which axes are spatial, and the step vector of each.
    let flips = get(&fields, &["space"]).map(|s| (s, space_to_lps(s)));
    let mut axis_steps: Vec<Option<DVec3>> = vec![None; dimension];
    let mut oriented = false;
    if let Some(dirs) = get(&fields, &["space directions"]) {
        let tokens = vector_tokens(dirs);
        if tokens.len() != dimension {
            return Err(LoadError::header(
                name,
                "space directions",
                format!("has {} entries for {dimension} axes", tokens.len()),
            ));
        }
        for (a, t) in tokens.iter().enumerate() {
            if let Some(v) = parse_vector(name, "space directions", t)? {
                if v.len() != 3 {
                    return Err(LoadError::unsupported(
                        name,
                        "NRRD space",
                        format!("{}-dimensional space directions", v.len()),
                    ));
                }
                axis_steps[a] = Some(DVec3::new(v[0], v[1], v[2]));
            }
        }
        oriented = true;
    } else {
        // No orientation: spacings (or 1 mm) along the axes whose kind is spatial.
        let spacings: Vec<f64> = get(&fields, &["spacings"])
            .map(|s| {
                s.split_whitespace()
                    .map(|x| x.parse::<f64>().unwrap_or(f64::NAN))
                    .collect()
            })
            .unwrap_or_default();
        let kinds: Vec<String> = get(&fields, &["kinds"])
            .map(|s| s.split_whitespace().map(str::to_ascii_lowercase).collect())
            .unwrap_or_default();
        let mut spatial = 0;
        let mut bad_spacings = Vec::new();
        for (a, step) in axis_steps.iter_mut().enumerate() {
            let kind_ok = kinds
                .get(a)
                .is_none_or(|k| matches!(k.as_str(), "domain" | "space" | "???" | "none"));
            if kind_ok && spatial < 3 {
                let s = match spacings.get(a).copied() {
                    Some(s) if s.is_finite() && s > 0.0 => s,
                    Some(s) if s.is_finite() && s < 0.0 => {
                        bad_spacings
                            .push(format!("axis {a} is {s}; its magnitude {} mm is used", -s));
                        -s
                    }
                    Some(s) => {
                        bad_spacings.push(format!("axis {a} is {s}; 1 mm is assumed"));
                        1.0
                    }
                    None if !spacings.is_empty() => {
                        bad_spacings.push(format!("axis {a} has no value; 1 mm is assumed"));
                        1.0
                    }
                    None => 1.0,
                };
                let mut v = DVec3::ZERO;
                v[spatial] = s;
                *step = Some(v);
                spatial += 1;
            }
        }
        if !bad_spacings.is_empty() {
            warnings.push(format!(
                "header field spacings: {}",
                bad_spacings.join("; ")
            ));
        } else if spacings.is_empty() {
            warnings.push("no spacings and no space directions: 1 mm is assumed".to_owned());
        }
        warnings.push(
            "no space directions: the orientation is unknown; axes are assumed to be LPS"
                .to_owned(),
        );
    }
    let spatial: Vec<usize> = (0..dimension)
        .filter(|&a| axis_steps[a].is_some())
        .collect();
    if spatial.is_empty() || spatial.len() > 3 {
        return Err(LoadError::unsupported(
            name,
            "NRRD layout",
            format!("{} spatial axes (expected 1 to 3)", spatial.len()),
        ));
    }
    if spatial.windows(2).any(|w| w[1] != w[0] + 1) {
        return Err(LoadError::unsupported(
            name,
            "NRRD layout",
            "a non-spatial axis between spatial axes",
        ));
    }
    // Elements of the non-spatial axes before the first spatial one interleave with the voxels.
    let stride = raw::checked_product(&sizes[..spatial[0]]).unwrap_or(u64::MAX);
    let total = raw::checked_product(&sizes).unwrap_or(u64::MAX);
    let extra_axes: Vec<String> = (0..dimension)
        .filter(|a| !spatial.contains(a) && sizes[*a] > 1)
        .map(|a| format!("axis {a} ({} elements)", sizes[a]))
        .collect();
    if !extra_axes.is_empty() {
        warnings.push(format!(
            "non-spatial {}: the first element is shown",
            extra_axes.join(", ")
        ));
    }
    let mut dims = [1usize; 3];
    let mut steps = [DVec3::X, DVec3::Y, DVec3::Z];
    for (slot, &a) in spatial.iter().enumerate() {
        dims[slot] =
            usize::try_from(sizes[a]).map_err(|_| LoadError::header(name, "sizes", "too large"))?;
        steps[slot] = axis_steps[a].unwrap_or(DVec3::ONE);
    }
    if spatial.len() < 3 {
        // A 2D image: make the missing axes orthogonal unit steps.
        let n = steps[0]
            .cross(if spatial.len() == 2 {
                steps[1]
            } else {
                DVec3::Y
            })
            .normalize_or(DVec3::Z);
        if spatial.len() == 1 {
            steps[1] = n.cross(steps[0]).normalize_or(DVec3::Y);
        }
        steps[2] = n;
    }
    let count = input.voxel_count(dims, ty)?;
    let data_bytes_total = total.saturating_mul(ty.size() as u64);

    let mut origin = match get(&fields, &["space origin"]) {
        Some(o) => match parse_vector(name, "space origin", o)? {
            Some(v) if v.len() == 3 => DVec3::new(v[0], v[1], v[2]),
            _ => return Err(LoadError::header(name, "space origin", "expected (x,y,z)")),
        },
        None => DVec3::ZERO,
    };
    if oriented {
        match flips {
            Some((_, Some(f))) => {
                for s in &mut steps {
                    *s *= f;
                }
                origin *= f;
            }
            Some((space, None)) => warnings.push(format!(
                "space \"{space}\" is not anatomical; its axes are taken as LPS"
            )),
            None => warnings.push("no space field: the axes are taken as LPS".to_owned()),
        }
    }

    // The data bytes: attached after the blank line, or in the named data file.
    let (data_name, data_file): (String, Data<'_>) = match get(&fields, &["data file", "datafile"])
    {
        Some(df) => {
            let f = input.companions.data_file(
                name,
                "data file",
                df.trim(),
                ("NRRD data file", "multiple data files"),
                &mut warnings,
            )?;
            (f.name.clone(), f.data())
        }
        None => {
            let file_len = input.file.len();
            let data = data_start
                .and_then(|start| input.file.data().after(start as u64))
                .ok_or_else(|| {
                    LoadError::truncated(
                        name,
                        "NRRD header (no blank line before the data)",
                        file_len + 1,
                        file_len,
                    )
                })?;
            (name.to_owned(), data)
        }
    };
    let line_skip: usize = get(&fields, &["line skip", "lineskip"])
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let byte_skip: i64 = get(&fields, &["byte skip", "byteskip"])
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let Some(data) = data_file.skip_lines(&data_name, line_skip)? else {
        return Err(LoadError::truncated(
            &data_name,
            "line skip",
            line_skip as u64,
            0,
        ));
    };

    let endian = match get(&fields, &["endian"]).map(str::trim) {
        Some("big") => Endian::Big,
        Some("little") => Endian::Little,
        None => {
            if ty.size() > 1 {
                warnings.push("no endian field: little endian assumed".to_owned());
            }
            Endian::Little
        }
        Some(other) => {
            return Err(LoadError::header(
                name,
                "endian",
                format!("\"{other}\"; expected little or big"),
            ));
        }
    };
    let encoding = need(&["encoding"])?.trim().to_ascii_lowercase();
    // Only the first volume is read (a short file is still a broken file). Ascii data are
    // parsed into f64 first.
    let layout = SampleLayout {
        ty,
        endian,
        offset: 0,
        count: count as usize,
        stride_samples: usize::try_from(stride).unwrap_or(usize::MAX),
    };
    let decoded: Data<'_> = match encoding.as_str() {
        "raw" => {
            let skip = if byte_skip == -1 {
                // -1: the data are the last bytes of the file.
                data.len().checked_sub(data_bytes_total).ok_or_else(|| {
                    LoadError::truncated(&data_name, "NRRD raw data", data_bytes_total, data.len())
                })?
            } else {
                u64::try_from(byte_skip)
                    .map_err(|_| LoadError::header(name, "byte skip", format!("{byte_skip}")))?
            };
            data.after(skip)
                .ok_or_else(|| LoadError::truncated(&data_name, "byte skip", skip, data.len()))?
        }
        "gzip" | "gz" => {
            let skip = u64::try_from(byte_skip).map_err(|_| {
                LoadError::header(name, "byte skip", "-1 is only allowed with raw encoding")
            })?;
            // Straight from the stream into the voxels (the CRC-32 is checked at its end).
            let (voxels, _) = raw::inflate_voxels(
                &data_name,
                raw::Compression::Gzip,
                data,
                skip,
                layout,
                skip.saturating_add(data_bytes_total),
                input.limits,
            )?;
            return finish(name, &data_name, dims, steps, origin, voxels, warnings);
        }
        "ascii" | "text" | "txt" => {
            let voxels = ascii_voxels(&data_name, data, total, layout, input.limits)?;
            return finish(name, &data_name, dims, steps, origin, voxels, warnings);
        }
        other => {
            return Err(LoadError::unsupported(
                name,
                "NRRD encoding",
                other.to_owned(),
            ));
        }
    };
    let needed = total.saturating_mul(layout.ty.size() as u64);
    let voxels = raw::decode_present(
        &data_name,
        "NRRD data",
        decoded,
        needed,
        layout,
        input.limits,
    )?;
    finish(name, &data_name, dims, steps, origin, voxels, warnings)
}

/// The volume from its voxels and the header's geometry.
fn finish(
    name: &str,
    data_name: &str,
    dims: [usize; 3],
    steps: [DVec3; 3],
    origin: DVec3,
    voxels: crate::volume::Voxels,
    mut warnings: Vec<String>,
) -> Result<Volume, LoadError> {
    let grid = checked_grid(
        name,
        ("space directions", steps),
        ("space origin", origin),
        &mut warnings,
    )?;
    let source = raw::source_name(name, data_name);
    Ok(grid.volume(dims, voxels, source, warnings))
}

/// Parses whitespace- or comma-separated numbers (ascii encoding) straight into f32 voxels:
/// the first `total` numbers must all be numbers and present (a short file is a broken file),
/// and `layout`'s samples among them (its stride picks one component) become the voxels, as
/// the binary encodings' f64 samples would (no buffer of all the numbers is made).
fn ascii_voxels(
    file: &str,
    data: Data<'_>,
    total: u64,
    layout: SampleLayout,
    limits: &Limits,
) -> Result<crate::volume::Voxels, LoadError> {
    let bytes = total.saturating_mul(8);
    if bytes > limits.max_decompressed_bytes {
        return Err(LoadError::TooLarge {
            file: file.to_owned(),
            what: "ascii NRRD data".to_owned(),
            bytes,
            limit: limits.max_decompressed_bytes,
        });
    }
    raw::check_voxel_budget(file, layout.count as u64, 4, limits)?;
    let mut out = raw::try_vec::<f32>(file, "voxels", layout.count)?;
    let stride = layout.stride_samples.max(1);
    let seen = std::cell::Cell::new(0u64);
    let mut take = |tok: &[u8]| -> Result<(), LoadError> {
        if seen.get() >= total {
            return Ok(());
        }
        let v: f64 = std::str::from_utf8(tok)
            .ok()
            .and_then(|t| t.parse().ok())
            .ok_or_else(|| {
                let shown: String = String::from_utf8_lossy(tok).chars().take(40).collect();
                LoadError::header(file, "ascii data", format!("\"{shown}\" is not a number"))
            })?;
        let t = seen.get() as usize;
        if t.is_multiple_of(stride)
            && let Some(o) = out.get_mut(t / stride)
        {
            *o = v as f32;
        }
        seen.set(seen.get() + 1);
        Ok(())
    };
    let separator = |c: &u8| c.is_ascii_whitespace() || *c == b',';
    // The text a chunk at a time (read on demand, it is never all in memory); a token cut by a
    // chunk's end is carried into the next.
    let mut carry: Vec<u8> = Vec::new();
    let mut chunk = Vec::new();
    let mut at = 0u64;
    while at < data.len() {
        let n = (data.len() - at).min(1 << 20) as usize;
        chunk.resize(n, 0);
        data.read_at(file, at, &mut chunk)?;
        at += n as u64;
        let mut rest: &[u8] = &chunk;
        if !carry.is_empty() {
            let end = rest.iter().position(separator).unwrap_or(rest.len());
            carry.extend_from_slice(&rest[..end]);
            rest = &rest[end..];
            if rest.is_empty() && at < data.len() {
                if carry.len() > 1 << 20 {
                    let shown: String = String::from_utf8_lossy(&carry).chars().take(40).collect();
                    return Err(LoadError::header(
                        file,
                        "ascii data",
                        format!("\"{shown}...\" is over 1 MiB long, not a number"),
                    ));
                }
                continue;
            }
            take(&carry)?;
            carry.clear();
        }
        // The last token may go on in the next chunk.
        let cut = if at < data.len() {
            rest.iter().rposition(separator).map_or(0, |p| p + 1)
        } else {
            rest.len()
        };
        for tok in rest[..cut].split(separator).filter(|t| !t.is_empty()) {
            take(tok)?;
        }
        carry.extend_from_slice(&rest[cut..]);
        if seen.get() >= total {
            break;
        }
    }
    if !carry.is_empty() {
        take(&carry)?;
    }
    let seen = seen.get();
    if seen < total {
        return Err(LoadError::truncated(
            file,
            "NRRD data",
            bytes,
            seen.saturating_mul(8),
        ));
    }
    Ok(crate::volume::Voxels::F32(out))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;
    use crate::io::{InputFile, read_header};

    fn nrrd(header: &str, data: &[u8]) -> InputFile {
        let mut b = header.as_bytes().to_vec();
        b.extend_from_slice(data);
        InputFile::new("t.nrrd", b)
    }

    #[test]
    fn attached_raw_ras_and_list_axis() {
        // 2 components x 2 x 1 x 1: the first component of each voxel is read.
        let f = nrrd(
            "NRRD0004\ntype: short\ndimension: 4\nspace: right-anterior-superior\nsizes: 2 2 1 1\nspace directions: none (2,0,0) (0,3,0) (0,0,4)\nendian: big\nencoding: raw\nspace origin: (1,2,3)\n\n",
            &[0, 1, 0, 9, 0, 2, 0, 9],
        );
        let v = read_header(read, &f, &[]).unwrap();
        assert_eq!(v.dims, [2, 1, 1]);
        assert_eq!(v.to_f32(), vec![1.0, 2.0]);
        assert_eq!(v.spacing_mm, [2.0, 3.0, 4.0]);
        assert_eq!(v.origin_mm, [-1.0, -2.0, 3.0]);
        assert_eq!(v.direction.x_axis, DVec3::new(-1.0, 0.0, 0.0));
        assert!(v.warnings.iter().any(|w| w.contains("first element")));
    }

    #[test]
    fn detached_ascii_and_missing_data_file() {
        let hdr = InputFile::new(
            "dir/a.nhdr",
            b"NRRD0004\ntype: float\ndimension: 3\nsizes: 2 1 1\nspacings: 0.5 1 1\nencoding: ascii\ndata file: a.txt\n".to_vec(),
        );
        let r = read_header(read, &hdr, &[]);
        assert!(matches!(r, Err(LoadError::MissingDataFile { .. })), "{r:?}");
        let data = [InputFile::new("other/a.txt", b"1.5 -2\n".to_vec())];
        let v = read_header(read, &hdr, &data).unwrap();
        assert_eq!(v.to_f32(), vec![1.5, -2.0]);
        assert_eq!(v.spacing_mm[0], 0.5);
    }
}
