//! XLA FFI handlers (typed FFI, `api_version=1`) for the flat-state functions, written in Rust
//! against a minimal `#[repr(C)]` mirror of `xla/ffi/api/c_api.h` (API 0.3, as shipped by
//! jaxlib 0.10.2). The handlers are exported as PyCapsules (`_xla_ffi_capsules`) and registered
//! by `ukemi.jax` with `jax.ffi.register_ffi_target(name, capsule, platform="cpu")`.
//!
//! Calling convention (all handlers): argument 0 is the model handle, an unsigned 64-bit integer
//! array of any shape whose entries are all the same key (from [`model_handle`]; `vmap` with
//! `broadcast_all` tiles it), so a new model needs neither a new registration nor an attribute.
//! The other arguments and results are float64 arrays whose leading axes are batch axes
//! (identical for every argument; the Python layer broadcasts them), flattened and run in
//! parallel with rayon ([`flat::batched`]). Attributes: `with_params` (integer/bool scalar),
//! for the VJPs `kappa_grad` (f64; negative or NaN means `None`, the exact gradient), and for
//! the step and the rollout the optional `keep` (integer/bool, default 0: keep the forward pass
//! for the VJP that follows under differentiation, `ukemi_engine::gradients::kept`).
//!
//! | target                  | arguments                           | results                     |
//! |-------------------------|-------------------------------------|-----------------------------|
//! | `ukemi_flat_step`       | h, x (…,nx), u (…,nu), p (…,np)     | x⁺ (…,nx)                   |
//! | `ukemi_flat_step_vjp`   | h, x, u, p, g (…,nx)                | gx, gu, gp (shapes of x,u,p)|
//! | `ukemi_flat_rollout`    | h, x0 (…,nx), us (…,T,nu), p        | xs (…,T+1,nx)               |
//! | `ukemi_flat_rollout_vjp`| h, x0, us, p, g (…,T+1,nx)          | gx0, gus, gp                |
//!
//! `p` is read only when `with_params` is set; otherwise its gradient is written as zeros.
//! Failures never unwind into XLA: every engine error (shape, input, non-convergence, …), a
//! float32 buffer, a bad handle and a caught panic become an `XLA_FFI_Error` whose message
//! names the problem; JAX raises it as a `JaxRuntimeError`.
use std::collections::HashMap;
use std::ffi::{CStr, CString, c_char, c_void};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::ptr::NonNull;
use std::sync::{Arc, OnceLock, RwLock};

use pyo3::prelude::*;
use pyo3::types::{PyCapsule, PyDict};
use ukemi_engine::gradients::flat;
use ukemi_engine::{Error, Model};

use crate::gradients::models_for;
use crate::model::PyModel;

/// The subset of `xla/ffi/api/c_api.h` (XLA FFI API 0.3) the handlers use.
#[allow(non_camel_case_types, dead_code)]
pub mod abi {
    use std::ffi::{c_char, c_void};

    /// `XLA_FFI_API_MAJOR`, `XLA_FFI_API_MINOR` of the mirrored header.
    pub const API_MAJOR: i32 = 0;
    /// See [`API_MAJOR`].
    pub const API_MINOR: i32 = 3;
    /// `XLA_FFI_Extension_Metadata`.
    pub const EXTENSION_METADATA: i32 = 1;
    /// `XLA_FFI_ExecutionStage_EXECUTE`.
    pub const STAGE_EXECUTE: i32 = 3;
    /// `XLA_FFI_ArgType_BUFFER` / `XLA_FFI_RetType_BUFFER`.
    pub const BUFFER: i32 = 1;
    /// `XLA_FFI_AttrType_SCALAR`.
    pub const ATTR_SCALAR: i32 = 3;
    /// `XLA_FFI_Error_Code_INVALID_ARGUMENT`, `_FAILED_PRECONDITION`, `_INTERNAL`.
    pub const ERR_INVALID_ARGUMENT: i32 = 3;
    /// See [`ERR_INVALID_ARGUMENT`].
    pub const ERR_FAILED_PRECONDITION: i32 = 9;
    /// See [`ERR_INVALID_ARGUMENT`].
    pub const ERR_INTERNAL: i32 = 13;

    /// `XLA_FFI_DataType` values.
    pub mod dtype {
        pub const PRED: i32 = 1;
        pub const S8: i32 = 2;
        pub const S16: i32 = 3;
        pub const S32: i32 = 4;
        pub const S64: i32 = 5;
        pub const U8: i32 = 6;
        pub const U16: i32 = 7;
        pub const U32: i32 = 8;
        pub const U64: i32 = 9;
        pub const F16: i32 = 10;
        pub const F32: i32 = 11;
        pub const F64: i32 = 12;
        pub const BF16: i32 = 16;
    }

    /// Opaque `XLA_FFI_Error`.
    #[repr(C)]
    pub struct XLA_FFI_Error {
        _private: [u8; 0],
    }

    #[repr(C)]
    pub struct XLA_FFI_Extension_Base {
        pub struct_size: usize,
        pub type_: i32,
        pub next: *mut XLA_FFI_Extension_Base,
    }

    #[repr(C)]
    #[derive(Clone, Copy)]
    pub struct XLA_FFI_Api_Version {
        pub struct_size: usize,
        pub extension_start: *mut XLA_FFI_Extension_Base,
        pub major_version: i32,
        pub minor_version: i32,
    }

    #[repr(C)]
    pub struct XLA_FFI_Error_Create_Args {
        pub struct_size: usize,
        pub extension_start: *mut XLA_FFI_Extension_Base,
        pub message: *const c_char,
        pub errc: i32,
    }

    pub type XLA_FFI_Error_Create =
        unsafe extern "C" fn(args: *mut XLA_FFI_Error_Create_Args) -> *mut XLA_FFI_Error;

    /// The head of `XLA_FFI_Api`, up to and including `XLA_FFI_Error_Create` (the only entry
    /// used; later fields are never read through this type).
    #[repr(C)]
    pub struct XLA_FFI_Api {
        pub struct_size: usize,
        pub extension_start: *mut XLA_FFI_Extension_Base,
        pub api_version: XLA_FFI_Api_Version,
        pub internal_api: *const c_void,
        pub error_create: Option<XLA_FFI_Error_Create>,
    }

    #[repr(C)]
    pub struct XLA_FFI_Buffer {
        pub struct_size: usize,
        pub extension_start: *mut XLA_FFI_Extension_Base,
        pub dtype: i32,
        pub data: *mut c_void,
        pub rank: i64,
        pub dims: *const i64,
    }

    #[repr(C)]
    pub struct XLA_FFI_ByteSpan {
        pub ptr: *const c_char,
        pub len: usize,
    }

    #[repr(C)]
    pub struct XLA_FFI_Scalar {
        pub dtype: i32,
        pub value: *const c_void,
    }

    #[repr(C)]
    pub struct XLA_FFI_Args {
        pub struct_size: usize,
        pub extension_start: *mut XLA_FFI_Extension_Base,
        pub size: i64,
        pub types: *const i32,
        pub args: *const *mut c_void,
    }

    #[repr(C)]
    pub struct XLA_FFI_Rets {
        pub struct_size: usize,
        pub extension_start: *mut XLA_FFI_Extension_Base,
        pub size: i64,
        pub types: *const i32,
        pub rets: *const *mut c_void,
    }

    #[repr(C)]
    pub struct XLA_FFI_Attrs {
        pub struct_size: usize,
        pub extension_start: *mut XLA_FFI_Extension_Base,
        pub size: i64,
        pub types: *const i32,
        pub names: *const *const XLA_FFI_ByteSpan,
        pub attrs: *const *const c_void,
    }

    #[repr(C)]
    pub struct XLA_FFI_CallFrame {
        pub struct_size: usize,
        pub extension_start: *mut XLA_FFI_Extension_Base,
        pub api: *const XLA_FFI_Api,
        pub ctx: *mut c_void,
        pub stage: i32,
        pub args: XLA_FFI_Args,
        pub rets: XLA_FFI_Rets,
        pub attrs: XLA_FFI_Attrs,
        pub future: *mut c_void,
    }

    #[repr(C)]
    pub struct XLA_FFI_Metadata {
        pub struct_size: usize,
        pub api_version: XLA_FFI_Api_Version,
        pub traits: u32,
        pub state_type_id: i64,
    }

    #[repr(C)]
    pub struct XLA_FFI_Metadata_Extension {
        pub extension_base: XLA_FFI_Extension_Base,
        pub metadata: *mut XLA_FFI_Metadata,
    }

    /// `XLA_FFI_STRUCT_SIZE(type, last_field)`: offset of the last field plus its size.
    macro_rules! struct_size {
        ($t:ty, $f:ident, $ft:ty) => {
            std::mem::offset_of!($t, $f) + std::mem::size_of::<$ft>()
        };
    }
    /// `XLA_FFI_CallFrame_STRUCT_SIZE` (up to `attrs`).
    pub const CALL_FRAME_STRUCT_SIZE: usize = struct_size!(XLA_FFI_CallFrame, attrs, XLA_FFI_Attrs);
    /// `XLA_FFI_Api_Version_STRUCT_SIZE`.
    pub const API_VERSION_STRUCT_SIZE: usize =
        struct_size!(XLA_FFI_Api_Version, minor_version, i32);
    /// `XLA_FFI_Error_Create_Args_STRUCT_SIZE`.
    pub const ERROR_CREATE_ARGS_STRUCT_SIZE: usize =
        struct_size!(XLA_FFI_Error_Create_Args, errc, i32);
    /// `XLA_FFI_Metadata_STRUCT_SIZE` (up to `traits`; `state_type_id` came later).
    pub const METADATA_STRUCT_SIZE: usize = struct_size!(XLA_FFI_Metadata, traits, u32);
    /// `XLA_FFI_Metadata_Extension_STRUCT_SIZE`.
    pub const METADATA_EXTENSION_STRUCT_SIZE: usize =
        struct_size!(XLA_FFI_Metadata_Extension, metadata, *mut XLA_FFI_Metadata);
    /// Bytes of `XLA_FFI_Api` this mirror reads.
    pub const API_PREFIX_SIZE: usize =
        struct_size!(XLA_FFI_Api, error_create, Option<XLA_FFI_Error_Create>);
}

use abi::*;

// ------------------------------------------------------------------------------ model registry

/// Models reachable from handlers, keyed by the address of their shared allocation (the
/// registry keeps a clone, so the address stays unique while registered).
fn registry() -> &'static RwLock<HashMap<u64, Arc<Model>>> {
    static REG: OnceLock<RwLock<HashMap<u64, Arc<Model>>>> = OnceLock::new();
    REG.get_or_init(Default::default)
}

/// The FFI handle of a model (idempotent). The model stays registered until
/// [`release_model_handle`].
#[pyfunction]
#[pyo3(name = "_xla_model_handle")]
pub fn model_handle(model: &PyModel) -> u64 {
    let key = Arc::as_ptr(&model.inner) as usize as u64;
    let mut reg = registry().write().unwrap_or_else(|e| e.into_inner());
    reg.entry(key).or_insert_with(|| model.inner.clone());
    key
}

/// Forget a handle; returns whether it was registered.
#[pyfunction]
#[pyo3(name = "_xla_release_model_handle")]
pub fn release_model_handle(handle: u64) -> bool {
    let mut reg = registry().write().unwrap_or_else(|e| e.into_inner());
    reg.remove(&handle).is_some()
}

fn lookup(handle: u64) -> Option<Arc<Model>> {
    let reg = registry().read().unwrap_or_else(|e| e.into_inner());
    reg.get(&handle).cloned()
}

// ------------------------------------------------------------------------------------ errors

/// A handler failure: an `XLA_FFI_Error_Code` and a message.
#[derive(Debug)]
struct Fail {
    code: i32,
    msg: String,
}

impl Fail {
    fn arg(msg: impl Into<String>) -> Fail {
        Fail {
            code: ERR_INVALID_ARGUMENT,
            msg: msg.into(),
        }
    }
}

impl From<Error> for Fail {
    fn from(e: Error) -> Fail {
        let (class, code) = match &e {
            Error::InvalidModel { .. } => ("ModelError", ERR_INVALID_ARGUMENT),
            Error::Shape { .. } => ("ShapeError", ERR_INVALID_ARGUMENT),
            Error::InvalidInput { .. } => ("InputError", ERR_INVALID_ARGUMENT),
            Error::ModelMismatch { .. } => ("ModelMismatchError", ERR_INVALID_ARGUMENT),
            Error::Unsupported(_) => ("UnsupportedError", ERR_INVALID_ARGUMENT),
            Error::Mjcf { .. } => ("MjcfError", ERR_INVALID_ARGUMENT),
            Error::Urdf { .. } => ("UrdfError", ERR_INVALID_ARGUMENT),
            Error::NotConverged { .. } => ("ConvergenceError", ERR_FAILED_PRECONDITION),
        };
        Fail {
            code,
            msg: format!("{class}: {e}"),
        }
    }
}

type HResult<T> = std::result::Result<T, Fail>;

fn dtype_name(d: i32) -> &'static str {
    match d {
        dtype::PRED => "bool",
        dtype::S8 => "int8",
        dtype::S16 => "int16",
        dtype::S32 => "int32",
        dtype::S64 => "int64",
        dtype::U8 => "uint8",
        dtype::U16 => "uint16",
        dtype::U32 => "uint32",
        dtype::U64 => "uint64",
        dtype::F16 => "float16",
        dtype::F32 => "float32",
        dtype::F64 => "float64",
        dtype::BF16 => "bfloat16",
        _ => "an unsupported dtype",
    }
}

// ------------------------------------------------------------------------------ frame decoding

/// A decoded buffer argument or result, tied to the call's lifetime.
struct Buf<'a> {
    name: &'static str,
    dtype: i32,
    data: *mut c_void,
    dims: &'a [i64],
}

impl<'a> Buf<'a> {
    fn len(&self) -> usize {
        self.dims.iter().map(|&d| d.max(0) as usize).product()
    }

    fn shape(&self) -> String {
        let d: Vec<String> = self.dims.iter().map(|d| d.to_string()).collect();
        format!("({})", d.join(", "))
    }

    fn check_f64(&self) -> HResult<()> {
        if self.dtype != dtype::F64 {
            return Err(Fail::arg(format!(
                "TypeError: `{}` has dtype {}; ukemi computes in float64 (enable jax_enable_x64 \
                 and pass float64 arrays)",
                self.name,
                dtype_name(self.dtype)
            )));
        }
        Ok(())
    }

    /// The leading (batch) axes, after checking the trailing axes equal `tail` (`None`: any).
    fn lead(&self, tail: &[Option<usize>]) -> HResult<&'a [i64]> {
        let k = tail.len();
        let bad = self.dims.len() < k
            || self.dims[self.dims.len() - k..]
                .iter()
                .zip(tail)
                .any(|(&d, t)| t.is_some_and(|t| d != t as i64));
        if bad {
            let want: Vec<String> = tail
                .iter()
                .map(|t| t.map_or("?".into(), |t| t.to_string()))
                .collect();
            return Err(Fail::arg(format!(
                "ShapeError: shape of `{}`: expected (..., {}), got {}",
                self.name,
                want.join(", "),
                self.shape()
            )));
        }
        Ok(&self.dims[..self.dims.len() - k])
    }

    /// Check shape `lead + tail`.
    fn expect(&self, lead: &[i64], tail: &[usize]) -> HResult<()> {
        let want: Vec<i64> = lead
            .iter()
            .copied()
            .chain(tail.iter().map(|&t| t as i64))
            .collect();
        if self.dims != want.as_slice() {
            let w: Vec<String> = want.iter().map(|d| d.to_string()).collect();
            return Err(Fail::arg(format!(
                "ShapeError: shape of `{}`: expected ({}) (leading batch axes must agree), got {}",
                self.name,
                w.join(", "),
                self.shape()
            )));
        }
        Ok(())
    }

    fn f64s(&self) -> HResult<&'a [f64]> {
        self.check_f64()?;
        let n = self.len();
        if n == 0 {
            return Ok(&[]);
        }
        // SAFETY: XLA passes a dense row-major f64 buffer of `n` elements that outlives the call.
        Ok(unsafe { std::slice::from_raw_parts(self.data as *const f64, n) })
    }

    fn i32s_mut(&self) -> HResult<&'a mut [i32]> {
        if self.dtype != dtype::S32 {
            return Err(Fail::arg(format!(
                "TypeError: `{}` must be int32, got {}",
                self.name,
                dtype_name(self.dtype)
            )));
        }
        let n = self.len();
        if n == 0 {
            return Ok(&mut []);
        }
        // SAFETY: a result buffer of `n` i32, distinct from every other buffer.
        Ok(unsafe { std::slice::from_raw_parts_mut(self.data as *mut i32, n) })
    }

    fn f64s_mut(&self) -> HResult<&'a mut [f64]> {
        self.check_f64()?;
        let n = self.len();
        if n == 0 {
            return Ok(&mut []);
        }
        // SAFETY: a result buffer of `n` f64, distinct from every argument (no aliasing is
        // requested) and from the other results.
        Ok(unsafe { std::slice::from_raw_parts_mut(self.data as *mut f64, n) })
    }
}

/// A call frame, checked for size; accessors validate indices and types.
struct Frame<'a> {
    raw: &'a XLA_FFI_CallFrame,
}

impl<'a> Frame<'a> {
    fn counts(&self, nargs: usize, nrets: usize) -> HResult<()> {
        let (a, r) = (self.raw.args.size, self.raw.rets.size);
        if a != nargs as i64 || r != nrets as i64 {
            return Err(Fail::arg(format!(
                "expected {nargs} arguments and {nrets} results, got {a} and {r}"
            )));
        }
        Ok(())
    }

    /// SAFETY of the raw reads: XLA guarantees `types`/`args` have `size` entries, each a
    /// valid `XLA_FFI_Buffer` when the type is BUFFER; `counts` checked `i < size`.
    fn buffer(
        &self,
        ty: *const i32,
        ptrs: *const *mut c_void,
        i: usize,
        name: &'static str,
    ) -> HResult<Buf<'a>> {
        unsafe {
            if *ty.add(i) != BUFFER {
                return Err(Fail::arg(format!("`{name}` is not a buffer")));
            }
            let b = &*(*ptrs.add(i) as *const XLA_FFI_Buffer);
            let dims = if b.rank > 0 {
                std::slice::from_raw_parts(b.dims, b.rank as usize)
            } else {
                &[]
            };
            Ok(Buf {
                name,
                dtype: b.dtype,
                data: b.data,
                dims,
            })
        }
    }

    fn arg(&self, i: usize, name: &'static str) -> HResult<Buf<'a>> {
        self.buffer(self.raw.args.types, self.raw.args.args, i, name)
    }

    fn ret(&self, i: usize, name: &'static str) -> HResult<Buf<'a>> {
        self.buffer(self.raw.rets.types, self.raw.rets.rets, i, name)
    }

    /// A scalar attribute by name, as f64 (any float, integer or bool dtype).
    fn scalar(&self, name: &str) -> HResult<f64> {
        self.scalar_or(name, None)
    }

    /// The scalar attribute `name`, or `default` when it is absent (`None`: an error).
    fn scalar_or(&self, name: &str, default: Option<f64>) -> HResult<f64> {
        let a = &self.raw.attrs;
        for i in 0..a.size.max(0) as usize {
            // SAFETY: `size` entries of types/names/attrs; names are byte spans.
            unsafe {
                let span = &**a.names.add(i);
                let key = std::slice::from_raw_parts(span.ptr as *const u8, span.len);
                if key != name.as_bytes() {
                    continue;
                }
                if *a.types.add(i) != ATTR_SCALAR {
                    return Err(Fail::arg(format!("attribute `{name}` must be a scalar")));
                }
                let s = &*(*a.attrs.add(i) as *const XLA_FFI_Scalar);
                let v = s.value;
                return match s.dtype {
                    dtype::F64 => Ok(*(v as *const f64)),
                    dtype::F32 => Ok(*(v as *const f32) as f64),
                    dtype::PRED | dtype::S8 | dtype::U8 => Ok(*(v as *const u8) as f64),
                    dtype::S16 => Ok(*(v as *const i16) as f64),
                    dtype::U16 => Ok(*(v as *const u16) as f64),
                    dtype::S32 => Ok(*(v as *const i32) as f64),
                    dtype::U32 => Ok(*(v as *const u32) as f64),
                    dtype::S64 => Ok(*(v as *const i64) as f64),
                    dtype::U64 => Ok(*(v as *const u64) as f64),
                    d => Err(Fail::arg(format!(
                        "attribute `{name}` has unsupported dtype {}",
                        dtype_name(d)
                    ))),
                };
            }
        }
        default.ok_or_else(|| Fail::arg(format!("missing attribute `{name}`")))
    }

    fn flag(&self, name: &str) -> HResult<bool> {
        Ok(self.scalar(name)? != 0.0)
    }

    /// An optional flag attribute (false when absent).
    fn optional_flag(&self, name: &str) -> HResult<bool> {
        Ok(self.scalar_or(name, Some(0.0))? != 0.0)
    }

    /// `kappa_grad`: negative or NaN means exact gradients (`None`).
    fn kappa(&self) -> HResult<Option<f64>> {
        let k = self.scalar("kappa_grad")?;
        Ok((k >= 0.0).then_some(k))
    }

    /// The model of argument 0 (a uint64/int64 handle array, every entry the same key).
    fn model(&self) -> HResult<Arc<Model>> {
        let b = self.arg(0, "model_handle")?;
        let n = b.len();
        if !matches!(b.dtype, dtype::U64 | dtype::S64) || n == 0 {
            return Err(Fail::arg(format!(
                "`model_handle` must be a non-empty uint64 array, got {} {}",
                dtype_name(b.dtype),
                b.shape()
            )));
        }
        // SAFETY: `n` 8-byte integers (checked dtype).
        let keys = unsafe { std::slice::from_raw_parts(b.data as *const u64, n) };
        if keys.iter().any(|&k| k != keys[0]) {
            return Err(Fail::arg(
                "`model_handle` entries differ: one call runs one model",
            ));
        }
        lookup(keys[0]).ok_or_else(|| {
            Fail::arg(format!(
                "unknown ukemi model handle {} (not registered, or released)",
                keys[0]
            ))
        })
    }
}

/// Run `f` over a batch of `b` elements: one model, or one per element when `params` is given;
/// a single element runs on the calling thread (no rayon hand-off).
fn run_batch<T: Send>(
    model: &Model,
    params: Option<&[f64]>,
    b: usize,
    f: impl Fn(&Model, usize) -> ukemi_engine::Result<T> + Sync,
) -> HResult<Vec<T>> {
    match params {
        None if b == 1 => Ok(vec![f(model, 0)?]),
        None => Ok(flat::batched(std::slice::from_ref(model), b, f)?),
        Some(p) => {
            let models = models_for(model, Some(p), b)?;
            if b == 1 {
                Ok(vec![f(&models[0], 0)?])
            } else {
                Ok(flat::batched(&models, b, f)?)
            }
        }
    }
}

fn batch_of(lead: &[i64]) -> usize {
    lead.iter().map(|&d| d.max(0) as usize).product()
}

/// Write per-element outputs of length `n` into `out` (`b * n`).
fn scatter(out: &mut [f64], parts: impl IntoIterator<Item = Vec<f64>>, n: usize) {
    for (chunk, part) in out.chunks_mut(n.max(1)).zip(parts) {
        chunk.copy_from_slice(&part);
    }
}

// ---------------------------------------------------------------------------------- handlers

fn step_impl(f: &Frame) -> HResult<()> {
    f.counts(4, 1)?;
    let m = f.model()?;
    let with_params = f.flag("with_params")?;
    // under differentiation: keep the solved step for the VJP (`ukemi_engine::gradients::kept`)
    let keep = f.optional_flag("keep")?;
    let (n, nu, np) = (flat::nx(&m), m.nu(), m.params().len());
    let x = f.arg(1, "x")?;
    let lead = x.lead(&[Some(n)])?;
    let u = f.arg(2, "u")?;
    u.expect(lead, &[nu])?;
    let p = f.arg(3, "params")?;
    if with_params {
        p.expect(lead, &[np])?;
    }
    let out = f.ret(0, "x_next")?;
    out.expect(lead, &[n])?;
    let (xs, us, ps) = (x.f64s()?, u.f64s()?, p.f64s()?);
    let out = out.f64s_mut()?;
    let b = batch_of(lead);
    let res = run_batch(&m, with_params.then_some(ps), b, |mm, i| {
        flat::step_kept(mm, &xs[i * n..(i + 1) * n], &us[i * nu..(i + 1) * nu], keep)
    })?;
    scatter(out, res, n);
    Ok(())
}

/// Like `step_impl`, plus a status output (…,) int32; non-convergence is reported there (the
/// last iterate is returned) instead of failing the call.
fn step_status_impl(f: &Frame) -> HResult<()> {
    f.counts(4, 2)?;
    let m = f.model()?;
    let with_params = f.flag("with_params")?;
    let (n, nu, np) = (flat::nx(&m), m.nu(), m.params().len());
    let x = f.arg(1, "x")?;
    let lead = x.lead(&[Some(n)])?;
    let u = f.arg(2, "u")?;
    u.expect(lead, &[nu])?;
    let p = f.arg(3, "params")?;
    if with_params {
        p.expect(lead, &[np])?;
    }
    let out = f.ret(0, "x_next")?;
    out.expect(lead, &[n])?;
    let status = f.ret(1, "status")?;
    status.expect(lead, &[])?;
    let (xs, us, ps) = (x.f64s()?, u.f64s()?, p.f64s()?);
    let (out, status) = (out.f64s_mut()?, status.i32s_mut()?);
    let b = batch_of(lead);
    let res = run_batch(&m, with_params.then_some(ps), b, |mm, i| {
        flat::step_with_status(mm, &xs[i * n..(i + 1) * n], &us[i * nu..(i + 1) * nu])
    })?;
    for (i, (xn, st)) in res.into_iter().enumerate() {
        out[i * n..(i + 1) * n].copy_from_slice(&xn);
        status[i] = i32::from(st);
    }
    Ok(())
}

fn step_vjp_impl(f: &Frame) -> HResult<()> {
    f.counts(5, 3)?;
    let m = f.model()?;
    let with_params = f.flag("with_params")?;
    let kappa = f.kappa()?;
    let (n, nu, np) = (flat::nx(&m), m.nu(), m.params().len());
    let x = f.arg(1, "x")?;
    let lead = x.lead(&[Some(n)])?;
    let u = f.arg(2, "u")?;
    u.expect(lead, &[nu])?;
    let p = f.arg(3, "params")?;
    if with_params {
        p.expect(lead, &[np])?;
    }
    let g = f.arg(4, "cotangent")?;
    g.expect(lead, &[n])?;
    let (gx, gu, gp) = (
        f.ret(0, "grad_x")?,
        f.ret(1, "grad_u")?,
        f.ret(2, "grad_params")?,
    );
    gx.expect(lead, &[n])?;
    gu.expect(lead, &[nu])?;
    if gp.dims != p.dims {
        return Err(Fail::arg("`grad_params` must have the shape of `params`"));
    }
    let (xs, us, ps, gs) = (x.f64s()?, u.f64s()?, p.f64s()?, g.f64s()?);
    let (gx, gu, gp) = (gx.f64s_mut()?, gu.f64s_mut()?, gp.f64s_mut()?);
    let b = batch_of(lead);
    let res = run_batch(&m, with_params.then_some(ps), b, |mm, i| {
        flat::step_vjp(
            mm,
            &xs[i * n..(i + 1) * n],
            &us[i * nu..(i + 1) * nu],
            &gs[i * n..(i + 1) * n],
            kappa,
            with_params,
        )
    })?;
    gp.fill(0.0);
    for (i, (ax, au, ap)) in res.into_iter().enumerate() {
        gx[i * n..(i + 1) * n].copy_from_slice(&ax);
        gu[i * nu..(i + 1) * nu].copy_from_slice(&au);
        if with_params {
            gp[i * np..(i + 1) * np].copy_from_slice(&ap);
        }
    }
    Ok(())
}

fn rollout_impl(f: &Frame) -> HResult<()> {
    f.counts(4, 1)?;
    let m = f.model()?;
    let with_params = f.flag("with_params")?;
    // under differentiation: keep the forward pass for the VJP (`ukemi_engine::gradients::kept`)
    let keep = f.optional_flag("keep")?;
    let (n, nu, np) = (flat::nx(&m), m.nu(), m.params().len());
    let x0 = f.arg(1, "x0")?;
    let lead = x0.lead(&[Some(n)])?;
    let us = f.arg(2, "us")?;
    us.lead(&[None, Some(nu)])?;
    let t = us.dims[us.dims.len() - 2].max(0) as usize;
    us.expect(lead, &[t, nu])?;
    let p = f.arg(3, "params")?;
    if with_params {
        p.expect(lead, &[np])?;
    }
    let out = f.ret(0, "xs")?;
    out.expect(lead, &[t + 1, n])?;
    let (x0s, uss, ps) = (x0.f64s()?, us.f64s()?, p.f64s()?);
    let out = out.f64s_mut()?;
    let b = batch_of(lead);
    let res = run_batch(&m, with_params.then_some(ps), b, |mm, i| {
        flat::rollout_kept(
            mm,
            &x0s[i * n..(i + 1) * n],
            &uss[i * t * nu..(i + 1) * t * nu],
            t,
            keep,
        )
    })?;
    scatter(out, res, (t + 1) * n);
    Ok(())
}

fn rollout_vjp_impl(f: &Frame) -> HResult<()> {
    f.counts(5, 3)?;
    let m = f.model()?;
    let with_params = f.flag("with_params")?;
    let kappa = f.kappa()?;
    let (n, nu, np) = (flat::nx(&m), m.nu(), m.params().len());
    let x0 = f.arg(1, "x0")?;
    let lead = x0.lead(&[Some(n)])?;
    let us = f.arg(2, "us")?;
    us.lead(&[None, Some(nu)])?;
    let t = us.dims[us.dims.len() - 2].max(0) as usize;
    us.expect(lead, &[t, nu])?;
    let p = f.arg(3, "params")?;
    if with_params {
        p.expect(lead, &[np])?;
    }
    let g = f.arg(4, "cotangent")?;
    g.expect(lead, &[t + 1, n])?;
    let (gx, gu, gp) = (
        f.ret(0, "grad_x0")?,
        f.ret(1, "grad_us")?,
        f.ret(2, "grad_params")?,
    );
    gx.expect(lead, &[n])?;
    gu.expect(lead, &[t, nu])?;
    if gp.dims != p.dims {
        return Err(Fail::arg("`grad_params` must have the shape of `params`"));
    }
    let (x0s, uss, ps, gs) = (x0.f64s()?, us.f64s()?, p.f64s()?, g.f64s()?);
    let (gx, gu, gp) = (gx.f64s_mut()?, gu.f64s_mut()?, gp.f64s_mut()?);
    let b = batch_of(lead);
    let res = run_batch(&m, with_params.then_some(ps), b, |mm, i| {
        flat::rollout_vjp(
            mm,
            &x0s[i * n..(i + 1) * n],
            &uss[i * t * nu..(i + 1) * t * nu],
            t,
            &gs[i * (t + 1) * n..(i + 1) * (t + 1) * n],
            kappa,
            with_params,
        )
    })?;
    gp.fill(0.0);
    for (i, (ax, au, ap)) in res.into_iter().enumerate() {
        gx[i * n..(i + 1) * n].copy_from_slice(&ax);
        gu[i * t * nu..(i + 1) * t * nu].copy_from_slice(&au);
        if with_params {
            gp[i * np..(i + 1) * np].copy_from_slice(&ap);
        }
    }
    Ok(())
}

// ------------------------------------------------------------------------------ entry points

/// Build an `XLA_FFI_Error` through the API table (NULL if the table is unusable).
///
/// # Safety
/// `api` is null or the `XLA_FFI_Api` of the call frame.
unsafe fn make_error(api: *const XLA_FFI_Api, code: i32, msg: &str) -> *mut XLA_FFI_Error {
    if api.is_null() {
        return std::ptr::null_mut();
    }
    // SAFETY: the caller's API table; its size is checked before reading `error_create`.
    let api = unsafe { &*api };
    let Some(create) = api
        .error_create
        .filter(|_| api.struct_size >= API_PREFIX_SIZE)
    else {
        return std::ptr::null_mut();
    };
    let c = CString::new(format!("ukemi: {msg}").replace('\0', " "))
        .unwrap_or_else(|_| CString::from(c"ukemi: error"));
    let mut args = XLA_FFI_Error_Create_Args {
        struct_size: ERROR_CREATE_ARGS_STRUCT_SIZE,
        extension_start: std::ptr::null_mut(),
        message: c.as_ptr() as *const c_char,
        errc: code,
    };
    // SAFETY: XLA copies the message into its status before returning.
    unsafe { create(&mut args) }
}

/// The metadata probe: report the API version this mirror implements, no traits, no state.
///
/// # Safety
/// `ext` is the frame's metadata extension.
unsafe fn populate_metadata(
    api: *const XLA_FFI_Api,
    ext: *mut XLA_FFI_Metadata_Extension,
) -> *mut XLA_FFI_Error {
    unsafe {
        let ext = &mut *ext;
        if ext.extension_base.struct_size < METADATA_EXTENSION_STRUCT_SIZE || ext.metadata.is_null()
        {
            return make_error(api, ERR_INVALID_ARGUMENT, "metadata extension too small");
        }
        let md = &mut *ext.metadata;
        if md.struct_size < METADATA_STRUCT_SIZE {
            return make_error(api, ERR_INVALID_ARGUMENT, "metadata struct too small");
        }
        md.api_version = XLA_FFI_Api_Version {
            struct_size: API_VERSION_STRUCT_SIZE,
            extension_start: std::ptr::null_mut(),
            major_version: API_MAJOR,
            minor_version: API_MINOR,
        };
        md.traits = 0;
        if md.struct_size >= std::mem::size_of::<XLA_FFI_Metadata>() {
            md.state_type_id = 0;
        }
        std::ptr::null_mut()
    }
}

/// Common entry: metadata probe, stage and size checks, then `body` with panics caught.
///
/// # Safety
/// `frame` is the call frame XLA passes to a handler.
unsafe fn entry(
    frame: *mut XLA_FFI_CallFrame,
    body: fn(&Frame) -> HResult<()>,
) -> *mut XLA_FFI_Error {
    if frame.is_null() {
        return std::ptr::null_mut();
    }
    // SAFETY: a live call frame for the duration of the call.
    let raw = unsafe { &*frame };
    let api = raw.api;
    if raw.struct_size < CALL_FRAME_STRUCT_SIZE {
        // SAFETY: `api` is the frame's table (null-checked inside).
        return unsafe { make_error(api, ERR_INVALID_ARGUMENT, "XLA FFI call frame too small") };
    }
    let ext = raw.extension_start;
    // SAFETY: a non-null extension chain head has at least `XLA_FFI_Extension_Base`.
    if !ext.is_null() && unsafe { (*ext).type_ } == EXTENSION_METADATA {
        return unsafe { populate_metadata(api, ext as *mut XLA_FFI_Metadata_Extension) };
    }
    if raw.stage != STAGE_EXECUTE {
        return std::ptr::null_mut();
    }
    let result = catch_unwind(AssertUnwindSafe(|| body(&Frame { raw })));
    let fail = match result {
        Ok(Ok(())) => return std::ptr::null_mut(),
        Ok(Err(f)) => f,
        Err(payload) => {
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            Fail {
                code: ERR_INTERNAL,
                msg: format!(
                    "InternalError: internal error in the ukemi engine (please report): {what}"
                ),
            }
        }
    };
    // SAFETY: the frame's API table.
    unsafe { make_error(api, fail.code, &fail.msg) }
}

macro_rules! handler {
    ($name:ident, $body:path) => {
        /// XLA FFI handler (see the module docs).
        ///
        /// # Safety
        /// Called by XLA with a valid call frame.
        pub unsafe extern "C" fn $name(frame: *mut XLA_FFI_CallFrame) -> *mut XLA_FFI_Error {
            // SAFETY: forwarded from XLA.
            unsafe { entry(frame, $body) }
        }
    };
}

handler!(ukemi_flat_step, step_impl);
handler!(ukemi_flat_step_vjp, step_vjp_impl);
handler!(ukemi_flat_step_status, step_status_impl);
handler!(ukemi_flat_rollout, rollout_impl);
handler!(ukemi_flat_rollout_vjp, rollout_vjp_impl);

type Handler = unsafe extern "C" fn(*mut XLA_FFI_CallFrame) -> *mut XLA_FFI_Error;

/// Target names and handlers.
pub const HANDLERS: [(&str, Handler); 5] = [
    ("ukemi_flat_step", ukemi_flat_step),
    ("ukemi_flat_step_status", ukemi_flat_step_status),
    ("ukemi_flat_step_vjp", ukemi_flat_step_vjp),
    ("ukemi_flat_rollout", ukemi_flat_rollout),
    ("ukemi_flat_rollout_vjp", ukemi_flat_rollout_vjp),
];

const CAPSULE_NAME: &CStr = c"xla._CUSTOM_CALL_TARGET";

/// `{target name: PyCapsule}` for `jax.ffi.register_ffi_target(..., api_version=1)`, and the
/// mirrored FFI API version as `(major, minor)`.
#[pyfunction]
#[pyo3(name = "_xla_ffi_capsules")]
pub fn capsules(py: Python<'_>) -> PyResult<(Bound<'_, PyDict>, (i32, i32))> {
    let d = PyDict::new(py);
    for (name, h) in HANDLERS {
        let ptr = NonNull::new(h as *mut c_void).expect("function pointer");
        // SAFETY: a static function pointer; no destructor needed.
        let cap = unsafe { PyCapsule::new_with_pointer(py, ptr, CAPSULE_NAME)? };
        d.set_item(name, cap)?;
    }
    Ok((d, (API_MAJOR, API_MINOR)))
}

#[cfg(test)]
mod tests {
    use std::mem::{offset_of, size_of};

    use super::abi::*;

    use super::{Fail, Frame, entry};

    thread_local! {
        static LAST: std::cell::RefCell<Option<(i32, String)>> = const { std::cell::RefCell::new(None) };
    }

    /// A stand-in for XLA's `XLA_FFI_Error_Create`: records the code and message.
    unsafe extern "C" fn fake_create(args: *mut XLA_FFI_Error_Create_Args) -> *mut XLA_FFI_Error {
        let a = unsafe { &*args };
        let msg = unsafe { std::ffi::CStr::from_ptr(a.message) }
            .to_string_lossy()
            .into_owned();
        LAST.with(|l| *l.borrow_mut() = Some((a.errc, msg)));
        std::ptr::NonNull::<XLA_FFI_Error>::dangling().as_ptr()
    }

    fn run(body: fn(&Frame) -> Result<(), Fail>) -> (bool, Option<(i32, String)>) {
        let null = std::ptr::null_mut();
        let api = XLA_FFI_Api {
            struct_size: API_PREFIX_SIZE,
            extension_start: null,
            api_version: XLA_FFI_Api_Version {
                struct_size: API_VERSION_STRUCT_SIZE,
                extension_start: null,
                major_version: API_MAJOR,
                minor_version: API_MINOR,
            },
            internal_api: std::ptr::null(),
            error_create: Some(fake_create),
        };
        let empty_args = XLA_FFI_Args {
            struct_size: size_of::<XLA_FFI_Args>(),
            extension_start: null,
            size: 0,
            types: std::ptr::null(),
            args: std::ptr::null(),
        };
        let mut frame = XLA_FFI_CallFrame {
            struct_size: CALL_FRAME_STRUCT_SIZE,
            extension_start: null,
            api: &api,
            ctx: std::ptr::null_mut(),
            stage: STAGE_EXECUTE,
            args: empty_args,
            rets: XLA_FFI_Rets {
                struct_size: size_of::<XLA_FFI_Rets>(),
                extension_start: null,
                size: 0,
                types: std::ptr::null(),
                rets: std::ptr::null(),
            },
            attrs: XLA_FFI_Attrs {
                struct_size: size_of::<XLA_FFI_Attrs>(),
                extension_start: null,
                size: 0,
                types: std::ptr::null(),
                names: std::ptr::null(),
                attrs: std::ptr::null(),
            },
            future: std::ptr::null_mut(),
        };
        LAST.with(|l| *l.borrow_mut() = None);
        let err = unsafe { entry(&mut frame, body) };
        (err.is_null(), LAST.with(|l| l.borrow_mut().take()))
    }

    #[test]
    fn panics_and_failures_become_ffi_errors_and_metadata_is_reported() {
        let (ok, last) = run(|_| Ok(()));
        assert!(ok && last.is_none());
        let (ok, last) = run(|_| panic!("boom"));
        let (code, msg) = last.expect("an error was created");
        assert!(!ok && code == ERR_INTERNAL && msg.contains("boom"), "{msg}");
        // a missing attribute and missing arguments are reported, not read out of bounds
        let (_, last) = run(|f| f.flag("with_params").map(|_| ()));
        assert!(last.unwrap().1.contains("missing attribute `with_params`"));
        let (_, last) = run(|f| f.counts(4, 1));
        assert!(last.unwrap().1.contains("expected 4 arguments"));
    }

    #[test]
    fn metadata_probe_reports_api_version() {
        let mut md = XLA_FFI_Metadata {
            struct_size: size_of::<XLA_FFI_Metadata>(),
            api_version: XLA_FFI_Api_Version {
                struct_size: 0,
                extension_start: std::ptr::null_mut(),
                major_version: -1,
                minor_version: -1,
            },
            traits: 7,
            state_type_id: 9,
        };
        let mut ext = XLA_FFI_Metadata_Extension {
            extension_base: XLA_FFI_Extension_Base {
                struct_size: METADATA_EXTENSION_STRUCT_SIZE,
                type_: EXTENSION_METADATA,
                next: std::ptr::null_mut(),
            },
            metadata: &mut md,
        };
        let err = unsafe {
            super::populate_metadata(
                std::ptr::null(),
                &mut ext as *mut XLA_FFI_Metadata_Extension,
            )
        };
        assert!(err.is_null());
        assert_eq!(
            (md.api_version.major_version, md.api_version.minor_version),
            (0, 3)
        );
        assert_eq!((md.traits, md.state_type_id), (0, 0));
    }

    #[test]
    fn abi_layout_matches_c_api_h_on_64_bit() {
        assert_eq!(size_of::<usize>(), 8, "layouts below assume LP64");
        assert_eq!(size_of::<XLA_FFI_Extension_Base>(), 24);
        assert_eq!(offset_of!(XLA_FFI_Extension_Base, type_), 8);
        assert_eq!(offset_of!(XLA_FFI_Extension_Base, next), 16);

        assert_eq!(size_of::<XLA_FFI_Api_Version>(), 24);
        assert_eq!(offset_of!(XLA_FFI_Api_Version, major_version), 16);
        assert_eq!(offset_of!(XLA_FFI_Api_Version, minor_version), 20);
        assert_eq!(API_VERSION_STRUCT_SIZE, 24);

        assert_eq!(offset_of!(XLA_FFI_Error_Create_Args, message), 16);
        assert_eq!(offset_of!(XLA_FFI_Error_Create_Args, errc), 24);
        assert_eq!(ERROR_CREATE_ARGS_STRUCT_SIZE, 28);

        assert_eq!(offset_of!(XLA_FFI_Api, api_version), 16);
        assert_eq!(offset_of!(XLA_FFI_Api, internal_api), 40);
        assert_eq!(offset_of!(XLA_FFI_Api, error_create), 48);
        assert_eq!(API_PREFIX_SIZE, 56);

        assert_eq!(size_of::<XLA_FFI_Buffer>(), 48);
        assert_eq!(offset_of!(XLA_FFI_Buffer, dtype), 16);
        assert_eq!(offset_of!(XLA_FFI_Buffer, data), 24);
        assert_eq!(offset_of!(XLA_FFI_Buffer, rank), 32);
        assert_eq!(offset_of!(XLA_FFI_Buffer, dims), 40);

        assert_eq!(size_of::<XLA_FFI_ByteSpan>(), 16);
        assert_eq!(size_of::<XLA_FFI_Scalar>(), 16);
        assert_eq!(offset_of!(XLA_FFI_Scalar, value), 8);

        assert_eq!(size_of::<XLA_FFI_Args>(), 40);
        assert_eq!(offset_of!(XLA_FFI_Args, size), 16);
        assert_eq!(offset_of!(XLA_FFI_Args, types), 24);
        assert_eq!(offset_of!(XLA_FFI_Args, args), 32);
        assert_eq!(size_of::<XLA_FFI_Rets>(), 40);
        assert_eq!(offset_of!(XLA_FFI_Rets, rets), 32);
        assert_eq!(size_of::<XLA_FFI_Attrs>(), 48);
        assert_eq!(offset_of!(XLA_FFI_Attrs, names), 32);
        assert_eq!(offset_of!(XLA_FFI_Attrs, attrs), 40);

        assert_eq!(offset_of!(XLA_FFI_CallFrame, api), 16);
        assert_eq!(offset_of!(XLA_FFI_CallFrame, ctx), 24);
        assert_eq!(offset_of!(XLA_FFI_CallFrame, stage), 32);
        assert_eq!(offset_of!(XLA_FFI_CallFrame, args), 40);
        assert_eq!(offset_of!(XLA_FFI_CallFrame, rets), 80);
        assert_eq!(offset_of!(XLA_FFI_CallFrame, attrs), 120);
        assert_eq!(offset_of!(XLA_FFI_CallFrame, future), 168);
        assert_eq!(size_of::<XLA_FFI_CallFrame>(), 176);
        assert_eq!(CALL_FRAME_STRUCT_SIZE, 168);

        assert_eq!(offset_of!(XLA_FFI_Metadata, api_version), 8);
        assert_eq!(offset_of!(XLA_FFI_Metadata, traits), 32);
        assert_eq!(offset_of!(XLA_FFI_Metadata, state_type_id), 40);
        assert_eq!(METADATA_STRUCT_SIZE, 36);
        assert_eq!(size_of::<XLA_FFI_Metadata>(), 48);
        assert_eq!(offset_of!(XLA_FFI_Metadata_Extension, metadata), 24);
        assert_eq!(METADATA_EXTENSION_STRUCT_SIZE, 32);
    }
}
