"""An independent torch reference of the single-scattering camera pass (render/drjit/scatter_march.py):
every camera sample of every ray at once, the trilinear lookup and its gradient from the 8 corner
values by hand, the local light by :func:`~mitsuba_platonic.render.drjit.scatter_march.local_depth`,
the camera's sum by cumulative products. Differentiable by autograd (float64 for gradcheck)."""

import math

import torch

from mitsuba_platonic.render.grids import extinction
from mitsuba_platonic.render.drjit.sky_light import EPSILON, local_depth, sky_offsets
from mitsuba_platonic.render.pytorch.single_scatter import SKY_DIRECTIONS, SKY_WEIGHTS, sweep
from mitsuba_platonic.views import camera_frames


def _lookup(packet, q):
    """packet (B, N, N, N, 8) [d, h, w]; q (B, K, 3) continuous index (d, h, w) → the 8 channels
    (B, K, 8) and ∂σ/∂q (B, K, 3). Corners outside the cube: σ, A_s, σ_s, O read 0; the albedo
    reads the nearest voxel inside."""
    b, n = packet.shape[0], packet.shape[1]
    flat = packet.reshape(b, -1, 8)
    i0 = torch.floor(q)
    t = q - i0
    i0 = i0.long()
    value = torch.zeros(*q.shape[:2], 8, dtype=packet.dtype)
    grad = torch.zeros(*q.shape[:2], 3, dtype=packet.dtype)
    for o in [(a, b_, c) for a in (0, 1) for b_ in (0, 1) for c in (0, 1)]:
        i = i0 + torch.tensor(o)
        inside = ((i >= 0) & (i < n)).all(-1)
        c = i.clamp(0, n - 1)
        rows = flat.gather(1, ((c[..., 0] * n + c[..., 1]) * n + c[..., 2])[..., None].expand(-1, -1, 8))
        rows = torch.where(inside[..., None], rows, rows * torch.tensor([0, 1, 1, 1, 0, 0, 0, 0], dtype=packet.dtype))
        w = [t[..., a] if o[a] else 1 - t[..., a] for a in range(3)]
        s = [1.0 if o[a] else -1.0 for a in range(3)]
        value = value + rows * (w[0] * w[1] * w[2])[..., None]
        grad = grad + rows[..., :1] * torch.stack([s[0] * w[1] * w[2], w[0] * s[1] * w[2], w[0] * w[1] * s[2]], -1)
    return value, grad


def reference_scatter_march(packet, views, light, m, spp, reach):
    """The image (B, 4, N, N) of the camera pass from the packet (B, N, N, N, 8), views (B, 3) and
    light (B, 9): sun direction, p E_s, L_sky (as render_scatter_march builds them)."""
    b, n = packet.shape[0], packet.shape[1]
    Δ, s = 2.0 / n, math.isqrt(spp)
    right, up, ω = (f.to(packet.dtype) for f in camera_frames(views))
    c = -1.0 + (torch.arange(n * s, dtype=packet.dtype) + 0.5) * (Δ / s)
    z = 1.0 - (torch.arange(n * m, dtype=packet.dtype) + 0.5) * (Δ / m)
    p = (z[None, :, None, None, None] * ω[:, None, None, None, :] + (-c)[None, None, :, None, None] * up[:, None, None, None, :]
         + c[None, None, None, :, None] * right[:, None, None, None, :])                 # (B, Nm, Ns, Ns, 3)
    q = torch.stack([(1 - p[..., 2]) * n / 2 - 0.5, (1 - p[..., 1]) * n / 2 - 0.5, (p[..., 0] + 1) * n / 2 - 0.5], -1)
    val, gq = _lookup(packet, q.reshape(b, -1, 3))
    σ, a, A, σ_s, O = val[..., 0], val[..., 1:4], val[..., 4], val[..., 5], val[..., 6]
    ℓ = reach * Δ
    grid = lambda d: torch.stack([-d[..., 2], -d[..., 1], d[..., 0]], -1) / Δ        # world → index (d, h, w)
    b_s = (gq * grid(light[:, :3].to(packet.dtype))[:, None, :]).sum(-1)
    e = (σ + b_s * ℓ).clamp_min(0.0)
    u = torch.where(b_s >= 0, 1.0, e / torch.where(e > 0, σ, 1.0))   # min(e/σ, 1); 1 where σ rises
    τ_s = local_depth(σ, b_s, ℓ) + 0.5 * ℓ * (σ_s - e) * u
    T_s = torch.exp(-τ_s) * (1 - A)
    Λ = 0
    for w, d, o in zip(SKY_WEIGHTS, SKY_DIRECTIONS, sky_offsets(reach)):
        ℓ_k = math.sqrt(sum(x * x for x in o)) * Δ              # the far read's distance along ω_k
        Λ = Λ + w * torch.exp(-local_depth(σ, (gq * grid(torch.tensor(d, dtype=packet.dtype))).sum(-1), ℓ_k))
    S = light[:, None, 3:6].to(packet.dtype) * T_s[..., None] + light[:, None, 6:9].to(packet.dtype) * ((1 - O) * Λ)[..., None]
    colour = (a * S).reshape(b, n * m, n * s, n * s, 3)
    opt = (σ * Δ / m).reshape(b, n * m, n * s, n * s)
    T = torch.exp(-(torch.cumsum(opt, 1) - opt))
    rgb = (T[..., None] * -torch.expm1(-opt)[..., None] * colour).sum(1)                 # (B, Ns, Ns, 3)
    alpha = -torch.expm1(-opt.sum(1))
    image = torch.cat([rgb.permute(0, 3, 1, 2), alpha[:, None]], 1)
    return torch.nn.functional.avg_pool2d(image, s)


def reference_sky_occlusion(σ, reach):
    """O (B, 1, N, N, N) of render/drjit/sky_light.py from σ (B, 1, N, N, N), in torch: the 14 sweeps of
    single_scatter.sweep (plane by plane, bilinear in-plane reads), the far reads as padded slices,
    the local factors from central differences."""
    b, n = σ.shape[0], σ.shape[-1]
    Δ = 2.0 / n
    p = torch.nn.functional.pad(σ[:, 0], (1, 1, 1, 1, 1, 1))
    grad = torch.stack([p[:, 2:, 1:-1, 1:-1] - p[:, :-2, 1:-1, 1:-1], p[:, 1:-1, 2:, 1:-1] - p[:, 1:-1, :-2, 1:-1],
                        p[:, 1:-1, 1:-1, 2:] - p[:, 1:-1, 1:-1, :-2]], -1) / (2 * Δ)
    num = den = EPSILON
    for w, d, o in zip(SKY_WEIGHTS, SKY_DIRECTIONS, sky_offsets(reach)):
        T = 1 - sweep(σ, torch.tensor([d] * b, dtype=torch.float64)).opacity[:, 0]
        padded = torch.nn.functional.pad(T, (2, 2, 2, 2, 2, 2), value=1.0)       # T = 1 outside the cube
        far = padded[:, 2 + o[0]:2 + o[0] + n, 2 + o[1]:2 + o[1] + n, 2 + o[2]:2 + o[2] + n]
        ω = torch.tensor([-d[2], -d[1], d[0]], dtype=σ.dtype)
        ℓ = math.sqrt(sum(x * x for x in o)) * Δ
        λ = w * torch.exp(-local_depth(σ[:, 0], (grad * ω).sum(-1), ℓ))
        num = num + λ * far
        den = den + λ
    return (1 - num / den)[:, None]


def _read(volume, offset):
    """volume (B, C, N, N, N) read trilinearly at every voxel centre moved by offset (B, 3) voxels
    [d, h, w], zero outside the cube: torch's grid_sample."""
    b, n = volume.shape[0], volume.shape[-1]
    c = (torch.arange(n, dtype=volume.dtype) + 0.5) * (2.0 / n) - 1.0
    d, h, w = torch.meshgrid(c, c, c, indexing="ij")
    base = torch.stack([w, h, d], dim=-1)[None]                   # grid_sample's (x, y, z) ← (w, h, d)
    shift = (offset.flip(-1) * (2.0 / n)).to(volume)[:, None, None, None, :]
    return torch.nn.functional.grid_sample(volume, base + shift, mode="bilinear", padding_mode="zeros",
                                           align_corners=False)


def reference_light_packet(volume, lights, reach):
    """The camera pass's packet (B, N, N, N, 8) of render/drjit/scatter_march.py in torch: σ, the albedo,
    the sun's sweep and σ read by grid_sample ``reach`` voxels towards the sun, the sky's O of
    :func:`reference_sky_occlusion`, a zero."""
    σ = extinction(volume[:, 3:])
    d = lights.direction.to(volume.dtype)
    sun = _read(torch.cat([sweep(σ, lights.direction).opacity, σ], 1), reach * torch.stack([-d[:, 2], -d[:, 1], d[:, 0]], -1))
    O = reference_sky_occlusion(σ, reach)
    return torch.cat([σ, volume[:, :3], sun, O, torch.zeros_like(σ)], 1).permute(0, 2, 3, 4, 1)
