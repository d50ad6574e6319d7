//! JavaScript's errors as text (wasm only): the one helper the page's file reading, downloads
//! and DICOMweb requests share.

use wasm_bindgen::JsValue;

/// A thrown JavaScript value as text: a string as it is, an `Error`'s `message`, else its
/// debug form.
pub fn error_text(e: &JsValue) -> String {
    e.as_string()
        .or_else(|| {
            js_sys::Reflect::get(e, &JsValue::from_str("message"))
                .ok()
                .and_then(|m| m.as_string())
        })
        .unwrap_or_else(|| format!("{e:?}"))
}
