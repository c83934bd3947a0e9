"""ukemi steps and rollouts as differentiable PyTorch functions.

The engine's forward and VJP are ``torch.library.custom_op`` kernels (with fake-tensor and
vmap rules); ``step``/``rollout`` wrap them in a ``torch.autograd.Function`` whose
``once_differentiable`` backward calls the VJP kernel — the combination that keeps
``loss.backward()``, ``gradcheck``, ``torch.func.grad``/``vmap``/``jacrev`` and
``torch.compile(fullgraph=True)`` working together. Tensors may live on any device (they are
copied to the host for the Rust engine); the computation is float64 and results are cast back
to the input's dtype.

The state is flat: ``x = [qpos, qvel]`` (nq + nv).
"""

from __future__ import annotations

import torch
from torch.autograd.function import once_differentiable

from . import _flat
from ._gradients import resolve_kappa

__all__ = ["rollout", "step", "step_jacobians"]

# Custom ops take primitive arguments only: models are passed by a registry key.
_MODELS: dict[int, object] = {}


def _key(model) -> int:
    _MODELS[id(model)] = model
    return id(model)


def _np(t: torch.Tensor):
    return t.detach().to("cpu", torch.float64).contiguous().numpy()


def _back(a, like: torch.Tensor) -> torch.Tensor:
    return torch.from_numpy(a).to(device=like.device, dtype=like.dtype)


def _kappa(k: float):
    return None if k < 0 else k


@torch.library.custom_op("ukemi::flat_step", mutates_args=())
def _step_op(key: int, x: torch.Tensor, u: torch.Tensor, p: torch.Tensor,
             with_params: bool, keep: bool = False) -> torch.Tensor:
    model = _MODELS[key]
    return _back(_flat.step(model, _np(x), _np(u), _np(p) if with_params else None, keep), x)


@_step_op.register_fake
def _(key, x, u, p, with_params, keep=False):
    shapes = [x.shape[:-1], u.shape[:-1]] + ([p.shape[:-1]] if with_params else [])
    return x.new_empty(torch.broadcast_shapes(*shapes) + (x.shape[-1],))


@torch.library.custom_op("ukemi::flat_step_vjp", mutates_args=())
def _step_vjp_op(key: int, kappa: float, x: torch.Tensor, u: torch.Tensor, p: torch.Tensor,
                 g: torch.Tensor, with_params: bool) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    model = _MODELS[key]
    gx, gu, gp = _flat.step_vjp(model, _np(x), _np(u), _np(p) if with_params else None, _np(g),
                                _kappa(kappa))
    return _back(gx, x), _back(gu, u), (_back(gp, p) if with_params else torch.zeros_like(p))


@_step_vjp_op.register_fake
def _(key, kappa, x, u, p, g, with_params):
    return torch.empty_like(x), torch.empty_like(u), torch.empty_like(p)


@torch.library.custom_op("ukemi::flat_rollout", mutates_args=())
def _rollout_op(key: int, x0: torch.Tensor, us: torch.Tensor, p: torch.Tensor,
                with_params: bool, keep: bool = False) -> torch.Tensor:
    model = _MODELS[key]
    return _back(_flat.rollout(model, _np(x0), _np(us), _np(p) if with_params else None, keep),
                 x0)


@_rollout_op.register_fake
def _(key, x0, us, p, with_params, keep=False):
    shapes = [x0.shape[:-1], us.shape[:-2]] + ([p.shape[:-1]] if with_params else [])
    return x0.new_empty(torch.broadcast_shapes(*shapes) + (us.shape[-2] + 1, x0.shape[-1]))


@torch.library.custom_op("ukemi::flat_rollout_vjp", mutates_args=())
def _rollout_vjp_op(key: int, kappa: float, x0: torch.Tensor, us: torch.Tensor, p: torch.Tensor,
                    g: torch.Tensor, with_params: bool) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    model = _MODELS[key]
    gx, gu, gp = _flat.rollout_vjp(model, _np(x0), _np(us), _np(p) if with_params else None,
                                   _np(g), _kappa(kappa))
    return _back(gx, x0), _back(gu, us), (_back(gp, p) if with_params else torch.zeros_like(p))


@_rollout_vjp_op.register_fake
def _(key, kappa, x0, us, p, g, with_params):
    return torch.empty_like(x0), torch.empty_like(us), torch.empty_like(p)


def _batched(info, in_dims, tensors):
    """Give every tensor an explicit leading batch axis (expanding unbatched ones)."""
    out = []
    for t, d in zip(tensors, in_dims):
        if d is None:
            out.append(t.unsqueeze(0).expand((info.batch_size,) + tuple(t.shape)))
        else:
            out.append(t.movedim(d, 0))
    return out


@_step_op.register_vmap
def _(info, in_dims, key, x, u, p, with_params, keep=False):
    x, u, p = _batched(info, in_dims[1:4], (x, u, p))
    return _step_op(key, x, u, p, with_params, keep), 0


@_step_vjp_op.register_vmap
def _(info, in_dims, key, kappa, x, u, p, g, with_params):
    x, u, p, g = _batched(info, in_dims[2:6], (x, u, p, g))
    return _step_vjp_op(key, kappa, x, u, p, g, with_params), (0, 0, 0)


@_rollout_op.register_vmap
def _(info, in_dims, key, x0, us, p, with_params, keep=False):
    x0, us, p = _batched(info, in_dims[1:4], (x0, us, p))
    return _rollout_op(key, x0, us, p, with_params, keep), 0


@_rollout_vjp_op.register_vmap
def _(info, in_dims, key, kappa, x0, us, p, g, with_params):
    x0, us, p, g = _batched(info, in_dims[2:6], (x0, us, p, g))
    return _rollout_vjp_op(key, kappa, x0, us, p, g, with_params), (0, 0, 0)


class _Step(torch.autograd.Function):
    generate_vmap_rule = True

    @staticmethod
    def forward(x, u, p, key, kappa, with_params, keep):
        # `keep`: a backward pass will follow, so the engine keeps the solved step for it
        return _step_op(key, x, u, p, with_params, keep)

    @staticmethod
    def setup_context(ctx, inputs, output):
        x, u, p, key, kappa, with_params, keep = inputs
        ctx.save_for_backward(x, u, p)
        ctx.meta = (key, kappa, with_params)

    @staticmethod
    @once_differentiable
    def backward(ctx, g):
        x, u, p = ctx.saved_tensors
        key, kappa, with_params = ctx.meta
        gx, gu, gp = _step_vjp_op(key, kappa, x, u, p, g.contiguous(), with_params)
        return gx, gu, gp, None, None, None, None


class _Rollout(torch.autograd.Function):
    generate_vmap_rule = True

    @staticmethod
    def forward(x0, us, p, key, kappa, with_params, keep):
        # `keep`: a backward pass will follow, so the engine keeps this forward pass for it
        return _rollout_op(key, x0, us, p, with_params, keep)

    @staticmethod
    def setup_context(ctx, inputs, output):
        x0, us, p, key, kappa, with_params, keep = inputs
        ctx.save_for_backward(x0, us, p)
        ctx.meta = (key, kappa, with_params)

    @staticmethod
    @once_differentiable
    def backward(ctx, g):
        x0, us, p = ctx.saved_tensors
        key, kappa, with_params = ctx.meta
        gx, gu, gp = _rollout_vjp_op(key, kappa, x0, us, p, g.contiguous(), with_params)
        return gx, gu, gp, None, None, None, None


def _check_dtype(name, t):
    if not isinstance(t, torch.Tensor):
        raise TypeError(f"`{name}` must be a torch.Tensor, got {type(t).__name__}")
    if t.dtype != torch.float64:
        raise TypeError(f"`{name}` must be float64 (got {t.dtype}): the engine works in float64; "
                        f"convert explicitly with `{name}.double()`")


def _args(model, x, u, params, kappa_grad, nu_shape):
    k = resolve_kappa(model, kappa_grad)
    for name, t in (("x", x), ("u", u), ("params", params)):
        if t is not None:
            _check_dtype(name, t)
    u = u if u is not None else x.new_zeros(nu_shape)
    p = params if params is not None else x.new_zeros((0,))
    return u, p, _key(model), (-1.0 if k is None else float(k)), params is not None


def step(model, x: torch.Tensor, u: torch.Tensor | None = None, params: torch.Tensor | None = None,
         kappa_grad=3e-4) -> torch.Tensor:
    """One differentiable step: ``x`` (..., nq + nv), ``u`` (..., nu), optional ``params``
    (..., nparams) in ``model.params`` layout. Gradients at ``kappa_grad`` (None: exact)."""
    u, p, key, k, wp = _args(model, x, u, params, kappa_grad, (model.nu,))
    keep = torch.is_grad_enabled() and any(t.requires_grad for t in (x, u, p))
    return _Step.apply(x, u, p, key, k, wp, keep)


def rollout(model, x0: torch.Tensor, us: torch.Tensor, params: torch.Tensor | None = None,
            kappa_grad=3e-4) -> torch.Tensor:
    """A differentiable rollout: ``x0`` (..., nq + nv), ``us`` (..., T, nu) → (..., T + 1, nq + nv)
    in one Rust call; the backward pass is the engine's reverse sweep."""
    u, p, key, k, wp = _args(model, x0, us, params, kappa_grad, (0, model.nu))
    keep = torch.is_grad_enabled() and any(t.requires_grad for t in (x0, u, p))
    return _Rollout.apply(x0, u, p, key, k, wp, keep)


def step_jacobians(model, x: torch.Tensor, u: torch.Tensor | None = None,
                   params: torch.Tensor | None = None, kappa_grad=3e-4):
    """Jacobians of one step in raw flat coordinates: ``(A (…, nx, nx), B (…, nx, nu))``, plus
    ``C`` (…, nx, nparams) when ``params`` is given; one engine linearisation per state (for
    iLQR-style trajectory optimisation). Not differentiable itself."""
    u, p, _, k, wp = _args(model, x, u, params, kappa_grad, (model.nu,))
    a, b, c = _flat.step_jacobians(model, _np(x), _np(u), _np(p) if wp else None,
                                   None if k < 0 else k, wp)
    out = (_back(a, x), _back(b, x))
    return out + (_back(c, x),) if wp else out
