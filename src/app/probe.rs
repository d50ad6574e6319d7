//! Feature values for the status bar: the texels under the mouse and at the crosshair, read
//! back from the displayed method's feature texture with a small asynchronous readback
//! (`render::probe`), one in flight at a time, never waited for.

use crate::gpu::GpuContext;
use crate::gpu::volume_texture::FeatureTexture;
use crate::render::probe::TexelProbe;

#[derive(Clone, Debug, PartialEq)]
struct Key {
    /// The feature entry read.
    entry: u64,
    voxels: Vec<[usize; 3]>,
}

/// The readback in flight and the last values read.
#[derive(Default)]
pub struct ProbeState {
    pending: Option<(Key, TexelProbe)>,
    last: Option<(Key, Vec<[f32; 4]>)>,
    failed: bool,
}

impl ProbeState {
    /// Whether a readback is in flight (the app keeps repainting until it lands).
    pub fn busy(&self) -> bool {
        self.pending.is_some()
    }

    /// Polls the readback in flight; starts one for `voxels` of `entry` when the last values
    /// are for something else.
    pub fn update(
        &mut self,
        gpu: &GpuContext,
        features: Option<(&FeatureTexture, u64)>,
        voxels: Vec<[usize; 3]>,
    ) {
        if let Some((key, probe)) = &mut self.pending {
            match probe.poll(gpu) {
                None => return,
                Some(Ok(values)) => {
                    self.last = Some((key.clone(), values));
                    self.pending = None;
                }
                Some(Err(e)) => {
                    // Not worth an error message: the status bar shows no values.
                    if !self.failed {
                        log::warn!("feature readback for the status bar failed: {e}");
                    }
                    self.failed = true;
                    self.pending = None;
                    return;
                }
            }
        }
        let Some((texture, entry)) = features else {
            return;
        };
        let want = Key { entry, voxels };
        if self.last.as_ref().map(|(k, _)| k) == Some(&want) || want.voxels.is_empty() {
            return;
        }
        let texels: Vec<[u32; 3]> = want
            .voxels
            .iter()
            .map(|v| v.map(|c| u32::try_from(c).unwrap_or(u32::MAX)))
            .collect();
        self.pending = Some((want, TexelProbe::start(gpu, texture, &texels)));
    }

    /// (V, A, B) at `voxel` of `entry`, if the last readback has it.
    pub fn value_at(&self, entry: u64, voxel: [usize; 3]) -> Option<[f32; 3]> {
        let (key, values) = self.last.as_ref()?;
        if key.entry != entry {
            return None;
        }
        let n = key.voxels.iter().position(|v| *v == voxel)?;
        values.get(n).map(|t| [t[0], t[1], t[2]])
    }
}
