//! The demo the app opens on when nothing is loaded: a small real CT (web/demo/, Apache-2.0, from
//! TotalSegmentator), fetched by the page as a static file or embedded in the native binary, and
//! its attribution as the app shows it.

/// The file name of the demo CT (also its URL relative to the page, under `demo/`).
pub const DEMO_FILE: &str = "aorta_ct_cropped.nii.gz";

/// Where the page fetches it (trunk copies web/demo/ to dist/demo/).
pub const DEMO_URL: &str = "demo/aorta_ct_cropped.nii.gz";

/// Its dimensions (checked by the tests and the browser test).
pub const DEMO_DIMS: [usize; 3] = [120, 126, 164];

pub const ATTRIBUTION: &str = "Demo CT: a cropped contrast-enhanced chest CT (heart, aorta, lung \
vessels), 120 x 126 x 164 voxels at 1.5 mm, from the TotalSegmentator project by Jakob \
Wasserthal and contributors (https://github.com/wasserth/TotalSegmentator, \
tests/reference_files/aorta_ct_cropped.nii.gz; Wasserthal et al., Radiology: Artificial \
Intelligence 2023), used unchanged under the Apache License 2.0.";

pub const LICENCE_URL: &str = "https://www.apache.org/licenses/LICENSE-2.0";

pub const PHANTOM_NOTE: &str = "Phantoms: the synthetic test objects of Wiemker et al. 2013 \
(spheres, cylinders, a slab, nodules beside vessels, bifurcations, an airway), built by this \
program in HU at 0.5 mm; \"demo\" is a 96 mm cube of nodules and vessels at 1 mm.";
