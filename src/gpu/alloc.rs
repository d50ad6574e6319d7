//! Allocations the device may refuse. A texture larger than the device's memory is not refused
//! by `create_texture`: the device reports an out-of-memory error, which outside an error scope
//! is fatal natively (wgpu-core's default handler panics) and only a console line in a browser,
//! after which every write to the texture fails. [`AllocCheck::around`] makes the allocation in
//! an out-of-memory error scope; natively the answer is in at once, in a browser a frame or a
//! few later, so its owner polls it before writing ([`AllocCheck::poll`]).

use std::future::Future;
use std::pin::Pin;
use std::task::{Context, Poll, Waker};

use super::GpuContext;

#[cfg(target_arch = "wasm32")]
type Answer = Pin<Box<dyn Future<Output = Option<wgpu::Error>>>>;
#[cfg(not(target_arch = "wasm32"))]
type Answer = Pin<Box<dyn Future<Output = Option<wgpu::Error>> + Send>>;

/// What the device said to an allocation.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Allocation {
    /// Not answered yet (in a browser).
    Waiting,
    Granted,
    /// Refused, in the device's words.
    Refused(String),
}

/// The device's answer to an allocation made in an out-of-memory error scope.
pub struct AllocCheck {
    answer: Option<Answer>,
    state: Allocation,
}

impl std::fmt::Debug for AllocCheck {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_tuple("AllocCheck").field(&self.state).finish()
    }
}

/// The device's words for a refusal: natively wgpu-core's, with their causes; in a browser
/// wgpu's own (its source is the JavaScript error object, which prints as "<WebGPU Error>").
fn words(e: &wgpu::Error) -> String {
    #[cfg(target_arch = "wasm32")]
    return e.to_string();
    #[cfg(not(target_arch = "wasm32"))]
    crate::error::chain(e)
}

impl AllocCheck {
    /// Runs `make` (creating textures or buffers) in an out-of-memory error scope, and asks
    /// for the answer once (natively it is in).
    pub fn around<T>(ctx: &GpuContext, make: impl FnOnce() -> T) -> (T, Self) {
        let scope = ctx.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let made = make();
        let mut check = Self {
            answer: Some(Box::pin(scope.pop())),
            state: Allocation::Waiting,
        };
        check.poll();
        (made, check)
    }

    /// The answer so far; asks the device again while it is [`Allocation::Waiting`].
    pub fn poll(&mut self) -> Allocation {
        if let Some(answer) = &mut self.answer {
            let mut cx = Context::from_waker(Waker::noop());
            if let Poll::Ready(error) = answer.as_mut().poll(&mut cx) {
                self.answer = None;
                self.state = match error {
                    None => Allocation::Granted,
                    Some(e) => Allocation::Refused(words(&e)),
                };
            }
        }
        self.state.clone()
    }
}
