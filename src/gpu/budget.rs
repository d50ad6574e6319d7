//! The GPU memory budget: how many bytes the volume textures (the intensity and the features)
//! may hold on this device, and the feature level that fits it.
//!
//! wgpu does not say how much memory a device has, and drivers refuse far less than that in one
//! allocation: SwiftShader 1 GiB (with a 2 GiB heap), Mesa's and AMD's Vulkan drivers 2 GiB, Metal
//! on Intel Macs about 1 GB; integrated GPUs, which most reading PCs have, share system memory,
//! and their practical ceiling is 1-2 GB (docs/performance.md, "Levels of detail"). So the
//! budget is a rule from the adapter's type, which the user may override (`--gpu-budget-mib`
//! natively, `?gpu_budget_mib=` in the page), and no single texture exceeds
//! [`MAX_ALLOCATION_BYTES`] whatever the budget.
//!
//! Over budget the features are kept max-pooled ([`feature_level`]): level L holds, per channel,
//! the maximum of each block of 2^L voxels per axis (rounded up, so never below a voxel's
//! full-resolution texel), exact for a MIP at its own resolution.

use crate::gpu::volume_texture::{FEATURE_TEXEL_BYTES, level_dims, texture_bytes};

/// The largest single texture Shapecast makes: what SwiftShader and Metal on Intel Macs grant
/// (many other drivers grant 2 GiB; none that matters grants less).
pub const MAX_ALLOCATION_BYTES: u64 = 1 << 30;

/// The coarsest level a feature texture may be pooled to (1/16 per axis): below it a
/// whole-body CT's features would be blocks of 1 cm.
pub const MAX_FEATURE_LEVEL: u32 = 4;

/// Where a budget comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BudgetSource {
    /// The rule for the adapter's type.
    Adapter,
    /// The user's (`--gpu-budget-mib`, `?gpu_budget_mib=`).
    User,
}

/// Bytes the volume textures may hold on the device.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GpuBudget {
    pub bytes: u64,
    pub source: BudgetSource,
}

impl GpuBudget {
    /// The rule for an adapter: a discrete GPU 3 GiB; an integrated, virtual or software one
    /// (lavapipe, SwiftShader), or one that does not say (a browser's WebGPU adapter tells no
    /// type), 1.5 GiB: SwiftShader's heap is 2 GiB in all, and the GPU process holds its own
    /// copies beside the textures.
    pub fn for_adapter(info: &wgpu::AdapterInfo) -> Self {
        let mib: u64 = match info.device_type {
            wgpu::DeviceType::DiscreteGpu => 3 << 10,
            _ => 1536,
        };
        Self {
            bytes: mib << 20,
            source: BudgetSource::Adapter,
        }
    }

    /// A budget the user gave, in MiB (at least 1).
    pub fn user_mib(mib: u64) -> Self {
        Self {
            bytes: mib.max(1).saturating_mul(1 << 20),
            source: BudgetSource::User,
        }
    }

    /// `user` if given, else the adapter's rule.
    pub fn choose(info: &wgpu::AdapterInfo, user_mib: Option<u64>) -> Self {
        user_mib.map_or_else(|| Self::for_adapter(info), Self::user_mib)
    }

    /// The budget in MiB (for messages).
    pub fn mib(&self) -> u64 {
        self.bytes >> 20
    }

    /// Bytes one method's features may hold beside the full-resolution intensity texture
    /// (R16Float) of a volume of `dims`.
    pub fn features_of(&self, dims: [u32; 3]) -> u64 {
        self.for_features(texture_bytes(dims, 2))
    }

    /// The feature level of a volume of `dims` within this budget ([`feature_level`]) on a
    /// device whose largest 3D texture is `max_dim`.
    pub fn feature_level(&self, dims: [u32; 3], max_dim: u32) -> u32 {
        feature_level(dims, self.features_of(dims), max_dim)
    }

    /// What is left for one method's features once `intensity_bytes` are held (at least a
    /// quarter of the budget: an intensity that takes more is over the budget itself, and the
    /// features then stay small), and never more than one allocation may be.
    pub fn for_features(&self, intensity_bytes: u64) -> u64 {
        self.bytes
            .saturating_sub(intensity_bytes)
            .max(self.bytes / 4)
            .min(MAX_ALLOCATION_BYTES)
    }
}

/// The finest feature level of a volume of `dims` whose texture fits `bytes` and the device's
/// largest 3D texture `max_dim` (0: full resolution), at most [`MAX_FEATURE_LEVEL`] (which is
/// then taken even where it does not fit: the texture's allocation says the rest).
pub fn feature_level(dims: [u32; 3], bytes: u64, max_dim: u32) -> u32 {
    (0..MAX_FEATURE_LEVEL)
        .find(|&level| {
            let d = level_dims(dims, level);
            texture_bytes(d, u64::from(FEATURE_TEXEL_BYTES)) <= bytes
                && d.iter().all(|&n| n <= max_dim)
        })
        .unwrap_or(MAX_FEATURE_LEVEL)
}

/// The budget on `ctx` (the user's MiB, if given) and the feature level of a volume of `dims`
/// within it, for a device whose largest 3D texture is `max_dim` (the CLI's `--webgpu-limits`
/// plans with WebGPU's).
pub fn plan_features(
    ctx: &crate::gpu::GpuContext,
    dims: [u32; 3],
    user_mib: Option<u64>,
    max_dim: u32,
) -> (GpuBudget, u32) {
    let budget = GpuBudget::choose(&ctx.adapter_info, user_mib);
    (budget, budget.feature_level(dims, max_dim))
}

/// What a level means to a reader: "full resolution", "1/2 resolution (max of 2 x 2 x 2
/// voxels)", ...
pub fn level_text(level: u32) -> String {
    if level == 0 {
        "full resolution".to_owned()
    } else {
        let f = 1u32 << level.min(31);
        format!("1/{f} resolution (max of {f} x {f} x {f} voxels)")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_body_features_are_pooled_within_every_budget() {
        let whole_body = [512, 512, 2000];
        // 2.1 GB at full resolution: over one allocation whatever the budget; 1/2 (262 MB) fits.
        let huge = GpuBudget::user_mib(8192).for_features(0);
        assert_eq!(huge, MAX_ALLOCATION_BYTES);
        assert_eq!(feature_level(whole_body, huge, 4096), 1);
        let budget = GpuBudget::user_mib(1536);
        let intensity = texture_bytes(whole_body, 2);
        assert_eq!(
            feature_level(whole_body, budget.for_features(intensity), 4096),
            1
        );
        // 768 MiB: the intensity (1000 MiB) is over it alone; the features get a quarter,
        // 192 MiB: 1/4 resolution (33 MB).
        let small = GpuBudget::user_mib(768).for_features(intensity);
        assert_eq!(small, 192 << 20);
        assert_eq!(feature_level(whole_body, small, 4096), 2);
        let rest = GpuBudget::user_mib(768).for_features(intensity / 8);
        assert_eq!(feature_level(whole_body, rest, 4096), 1);
        // A chest CT keeps its full resolution.
        let chest = [512, 512, 350];
        let b = GpuBudget::user_mib(1536).for_features(texture_bytes(chest, 2));
        assert_eq!(feature_level(chest, b, 2048), 0);
        // The device's largest 3D texture counts too.
        assert_eq!(feature_level([512, 512, 3000], 8 << 30, 2048), 1);
        assert_eq!(level_text(1), "1/2 resolution (max of 2 x 2 x 2 voxels)");
    }
}
