//! Hand-written DICOM slices for unit tests (explicit VR little endian, 16-bit signed CT).

/// What one synthetic slice says about itself.
#[derive(Clone, Debug)]
pub(crate) struct Slice {
    pub series_uid: String,
    pub sop_uid: String,
    pub instance_number: i32,
    pub rows: u16,
    pub cols: u16,
    pub position: [f64; 3],
    pub orientation: [f64; 6],
    pub pixel_spacing: [f64; 2],
    pub slope: f64,
    pub intercept: f64,
    /// Transfer syntax written into the file meta (the data set is always explicit LE).
    pub transfer_syntax: String,
    /// Row-major samples; `rows * cols` of them.
    pub pixels: Vec<i16>,
}

impl Slice {
    /// An axial slice `k` of a series: position (0, 0, 2.5 k), pixels `k * 100 + i`.
    pub(crate) fn axial(series: &str, k: i32, rows: u16, cols: u16) -> Self {
        Self {
            series_uid: series.to_owned(),
            sop_uid: format!("{series}.{k}"),
            instance_number: k + 1,
            rows,
            cols,
            position: [-10.0, -20.0, 2.5 * f64::from(k)],
            orientation: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
            pixel_spacing: [0.7, 0.6],
            slope: 1.0,
            intercept: -1024.0,
            transfer_syntax: "1.2.840.10008.1.2.1".to_owned(),
            pixels: (0..i32::from(rows) * i32::from(cols))
                .map(|i| (k * 100 + i) as i16)
                .collect(),
        }
    }

    pub(crate) fn bytes(&self) -> Vec<u8> {
        let ds = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{x}"))
                .collect::<Vec<_>>()
                .join("\\")
                .into_bytes()
        };
        let us = |v: u16| v.to_le_bytes().to_vec();
        let text = |s: &str| s.as_bytes().to_vec();
        let ct_image_storage = "1.2.840.10008.5.1.4.1.1.2";
        let d = elements(&[
            ((0x0008, 0x0016), b"UI", text(ct_image_storage)),
            ((0x0008, 0x0018), b"UI", text(&self.sop_uid)),
            ((0x0008, 0x0060), b"CS", text("CT")),
            ((0x0020, 0x000E), b"UI", text(&self.series_uid)),
            (
                (0x0020, 0x0013),
                b"IS",
                self.instance_number.to_string().into_bytes(),
            ),
            ((0x0020, 0x0032), b"DS", ds(&self.position)),
            ((0x0020, 0x0037), b"DS", ds(&self.orientation)),
            ((0x0028, 0x0002), b"US", us(1)),
            ((0x0028, 0x0004), b"CS", text("MONOCHROME2")),
            ((0x0028, 0x0010), b"US", us(self.rows)),
            ((0x0028, 0x0011), b"US", us(self.cols)),
            ((0x0028, 0x0030), b"DS", ds(&self.pixel_spacing)),
            ((0x0028, 0x0100), b"US", us(16)),
            ((0x0028, 0x0101), b"US", us(16)),
            ((0x0028, 0x0102), b"US", us(15)),
            ((0x0028, 0x0103), b"US", us(1)),
            ((0x0028, 0x1052), b"DS", ds(&[self.intercept])),
            ((0x0028, 0x1053), b"DS", ds(&[self.slope])),
            (
                (0x7FE0, 0x0010),
                b"OW",
                self.pixels.iter().flat_map(|p| p.to_le_bytes()).collect(),
            ),
        ]);
        let group = elements(&[
            ((0x0002, 0x0001), b"OB", vec![0, 1]),
            ((0x0002, 0x0002), b"UI", text(ct_image_storage)),
            ((0x0002, 0x0003), b"UI", text(&self.sop_uid)),
            ((0x0002, 0x0010), b"UI", text(&self.transfer_syntax)),
        ]);
        let mut out = vec![0u8; 128];
        out.extend_from_slice(b"DICM");
        element(
            &mut out,
            (0x0002, 0x0000),
            b"UL",
            &(group.len() as u32).to_le_bytes(),
        );
        out.extend_from_slice(&group);
        out.extend_from_slice(&d);
        out
    }
}

/// A data element: tag (group, element), VR and value.
type Element<'a> = ((u16, u16), &'a [u8; 2], Vec<u8>);

/// The elements, encoded one after another.
fn elements(list: &[Element<'_>]) -> Vec<u8> {
    let mut out = Vec::new();
    for (tag, vr, value) in list {
        element(&mut out, *tag, vr, value);
    }
    out
}

fn element(out: &mut Vec<u8>, tag: (u16, u16), vr: &[u8; 2], value: &[u8]) {
    let mut v = value.to_vec();
    if v.len() % 2 == 1 {
        v.push(if matches!(vr, b"UI" | b"OB") { 0 } else { b' ' });
    }
    out.extend_from_slice(&tag.0.to_le_bytes());
    out.extend_from_slice(&tag.1.to_le_bytes());
    out.extend_from_slice(vr);
    if matches!(vr, b"OB" | b"OW" | b"SQ" | b"UN" | b"UT") {
        out.extend_from_slice(&[0, 0]);
        out.extend_from_slice(&(v.len() as u32).to_le_bytes());
    } else {
        out.extend_from_slice(&(v.len() as u16).to_le_bytes());
    }
    out.extend_from_slice(&v);
}
