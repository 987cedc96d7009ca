"""A Mitsuba integrator that ray-marches VH, AO and EA through a heterogeneous medium's grids.

The scene holds the generator volume as a Mitsuba ``heterogeneous`` medium: its ``sigma_t``
grid is the density v (``scale`` = 1/Δ, the visual-hull extinction σ = v/Δ) and, for EA only,
its ``albedo`` grid is the colour. This integrator marches each camera ray through the
camera-space cube z_c ∈ [−1, 1] (the same region the closed-form layers resample), looks up
the *density* v at each sample and converts it per sample, so trilinear lookups interpolate
the same quantity as the closed form (docs/conventions.md, "Opacity and extinction").

Segments. With voxel size Δ = 2/N and ``step`` = h/Δ voxels, segment k covers camera depth
[k h, min((k + 1) h, 2)] from the front face; its length in voxels is s_k = min(step, N − k·step)
and its sample sits at fraction u of the segment: u = ½ (midpoint), or u ~ U[0, 1) per ray with
``jitter``. Per segment, the transmittance τ_k and opacity a_k = 1 − τ_k are

    VH:      τ_k = exp(−s_k v_k)                       (σ = v/Δ)
    AO, EA:  τ_k = (1 − v_k)^{s_k}                     (σ = −ln(1 − v)/Δ)

At ``step`` = 1, τ_k = 1 − v_k is computed as such: exact and differentiable at v = 1. At other
steps it is exp(s_k · log(1 − min(v, 1 − 1e-6))): the density is *clamped* to 1 − 1e-6 so the
log and its gradient stay finite (the gradient is 0 above the clamp).

Image formation, with T_k = Π_{j<k} τ_j:

    VH, AO:  ρ = 1 − Π_k τ_k                           (one channel, replicated in RGB)
    EA:      C = Σ_k T_k a_k c_k,   α = 1 − Π_k τ_k     (α is the AOV ``alpha``)

Early termination. With ``termination`` ε > 0 a ray stops once T ≤ ε, in the primal and in the
adjoint: an approximation whose image error is at most ε and whose gradient error the bench
measures. With ε = 0 (the default) the march is exact in value *and* gradient: the primal may
stop where T is exactly 0 (nothing behind is visible), but the adjoint always marches the whole
ray, because the gradient at an opaque sample k (τ_k = 0) still depends on everything behind it:
∂α/∂τ_k = −T_k U_k with U_k = Π_{j>k} τ_j, and ∂C/∂τ_k = T_k (R_k − c_k).

Adjoint (path replay, no division by τ so it stays exact when τ = 0). The backward pass
replays the ray front to back, recording T_k, then marches back to front accumulating the
suffix radiance R_k = Σ_{m>k} (Π_{k<j<m} τ_j) a_m c_m and suffix transmittance U_k = Π_{j>k} τ_j:

    ∂C/∂τ_k = T_k (R_k − c_k),    ∂C/∂c_k = T_k a_k,    ∂α/∂τ_k = ∂ρ/∂τ_k = −T_k U_k

and back-propagates δL·∂L/∂τ_k · τ_k(v) (+ the colour term) through the grid lookups.
Memory: one float per ray and segment.
"""

from __future__ import annotations

import math

from ..variant import ensure_variant

mi = ensure_variant()
import drjit as dr  # noqa: E402  (after the variant is set)

from ..drjit.marcher import V_MAX, n_segments, segment_transmittance  # noqa: E402  (one owner of the formulas)

__all__ = ["RayMarcher", "INTEGRATOR_NAME", "V_MAX"]

INTEGRATOR_NAME = "platonic_raymarch"



class RayMarcher(mi.ad.integrators.common.RBIntegrator):
    """Ray-marching VH / AO / EA integrator (see the module docstring for the maths).

    Properties: ``model`` ('vh' | 'ao' | 'ea'), ``resolution`` N (voxels per side), ``filter``,
    ``step`` (voxels, > 0), ``jitter`` (bool), ``termination`` (transmittance threshold ≥ 0),
    ``density`` (a ``gridvolume`` holding v) and, for EA, ``albedo`` (a ``gridvolume`` of colour).
    """

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self.model = props.get("model", "ea")
        self.resolution = int(props.get("resolution"))
        self.step = float(props.get("step", 1.0))
        self.jitter = bool(props.get("jitter", False))
        self.termination = float(props.get("termination", 0.0))
        self.filter = props.get("filter", "trilinear")
        self.density = props.get("density")
        self.albedo = props.get("albedo") if self.model == "ea" else None
        self.Δ = 2.0 / self.resolution
        self.n_steps = n_segments(self.resolution, self.step)

    def aov_names(self):
        return ["alpha"] if self.model == "ea" else []

    def to_string(self):
        return (f"RayMarcher[model={self.model}, N={self.resolution}, step={self.step}, "
                f"jitter={self.jitter}, termination={self.termination}]")

    # -- Sample positions and sensor rays --------------------------------------------------

    def sample_rays(self, scene, sensor, sampler):
        """Pixel-centre rays (a regular √spp × √spp sub-grid per pixel), or jittered with ``jitter``."""
        film = sensor.film()
        size = film.crop_size()
        spp = sampler.sample_count()
        idx = dr.arange(mi.UInt32, size.x * size.y * spp)
        pixel = idx // spp                                   # which pixel this sample belongs to
        sub = idx - pixel * spp                              # its index within the pixel
        pos = mi.Vector2u(pixel % size.x, pixel // size.x)
        if self.jitter:
            offset = sampler.next_2d()
        else:
            m = math.isqrt(spp)                              # spp is a perfect square (checked upstream)
            offset = (mi.Vector2f(mi.Float(sub % m), mi.Float(sub // m)) + 0.5) / m
        pos_f = mi.Vector2f(pos) + offset
        with dr.resume_grad():
            ray, weight = sensor.sample_ray_differential(
                time=0.0, sample1=0.0, sample2=pos_f / mi.ScalarVector2f(size), sample3=mi.Vector2f(0.0))
        # Box filter: splat into the pixel itself. The weight is 1 for an orthographic sensor; keep
        # it a Float (not a Spectrum) so Mitsuba's adjoint splatting of the alpha AOV type-checks.
        return ray, mi.Float(weight[0]), mi.Vector2f(pos)

    def _segment(self, ray, t0, u, k):
        """Sample point of segment k and its length s_k in voxels."""
        kf = mi.Float(k)
        s = dr.minimum(self.step, self.resolution - kf * self.step)   # the last segment may be short
        t = t0 + (kf * self.step + u * s) * self.Δ
        return ray(t), s

    def _padding_weight(self, p):
        """Weight that turns a clamped grid lookup at p into a zero-padded one (as ``grid_sample``).

        Per axis, with q the continuous voxel index (centres at 0 … N−1), trilinear lookups
        blend towards an empty voxel beyond each face: w(q) = clamp(min(q + 1, N − q), 0, 1),
        and the 3D weight is the product (trilinear is separable). Nearest lookups are 1 inside
        the cube (q ∈ [−½, N − ½)) and 0 outside.
        """
        N = self.resolution
        q = (p + 1.0) * (N / 2.0) - 0.5                       # continuous voxel index per axis
        if self.filter == "nearest":
            inside = dr.all((q >= -0.5) & (q < N - 0.5))
            return dr.select(inside, 1.0, 0.0)
        w = dr.clip(dr.minimum(q + 1.0, N - q), 0.0, 1.0)
        return w.x * w.y * w.z

    def _lookup(self, p, s, colour: bool = True):
        """Transmittance τ of a segment of s voxels at p, and the emitted colour c (EA only)."""
        it = dr.zeros(mi.Interaction3f)
        it.p = p
        pad = self._padding_weight(p)
        v = self.density.eval_1(it) * pad
        τ, _ = segment_transmittance(self.model, self.step == 1.0, v, s)   # the batched marcher's formula
        c = self.albedo.eval(it) * pad if (colour and self.albedo is not None) else None
        return τ, c

    # -- Primal and adjoint marches ----------------------------------------------------------

    def sample(self, mode, scene, sampler, ray, δL, δaovs, state_in, active, **kwargs):
        if mode == dr.ADMode.Forward:
            raise NotImplementedError("the ray marcher supports primal and reverse-mode rendering only")
        ray = mi.Ray3f(ray)
        # The camera-space depth interval starts where depth z_c = +1 (the cube's front face)
        t0 = -dr.dot(ray.o, ray.d) - 1.0
        # Where in each segment the sample sits: the midpoint, or uniform with jitter
        u = sampler.next_1d() if self.jitter else mi.Float(0.5)
        if mode == dr.ADMode.Primal:
            T, C = self._march(ray, t0, u, mi.Bool(active))
            if self.model == "ea":
                return C, mi.Bool(True), [1.0 - T], C
            ρ = mi.Spectrum(1.0 - T)
            return ρ, mi.Bool(True), [], ρ
        δρ = dr.sum(δL)                                       # VH/AO: ρ is replicated in R, G, B
        δα = δaovs[0] if self.model == "ea" else mi.Float(0.0)
        self._adjoint(ray, t0, u, mi.Bool(active), mi.Spectrum(δL), δρ, δα)
        return mi.Spectrum(0.0), mi.Bool(True), [], None

    def _emit(self, C, T, τ, c):
        """EA: C += T (1 − τ) c; VH and AO emit nothing."""
        return C + T * (1.0 - τ) * c if self.model == "ea" else C

    @dr.syntax
    def _march(self, ray, t0, u, active):
        """Primal: front-to-back march → (final transmittance T, emitted colour C)."""
        k = mi.UInt32(0)
        T = mi.Float(1.0)
        C = mi.Spectrum(0.0)
        while active:
            p, s = self._segment(ray, t0, u, k)
            τ, c = self._lookup(p, s)
            C = self._emit(C, T, τ, c)
            T *= τ
            k += 1
            # nothing behind T = 0 is visible, so the image is exact with ε = 0 too
            active &= (k < self.n_steps) & (T > self.termination)
        return T, C

    def _backpropagate(self, p, s, T_k, R, U, δL, δρ, δα):
        """Back-propagate segment k's adjoint into the grids; return its detached (τ, c)."""
        with dr.resume_grad():
            τ, c = self._lookup(p, s)
            if self.model == "ea":
                # ∂C/∂τ = T (R − c),  ∂C/∂c = T a,  ∂α/∂τ = −T U
                g = dr.sum(δL * T_k * (R - dr.detach(c))) - δα * T_k * U
                dr.backward_from(g * τ + dr.sum(δL * T_k * (1.0 - dr.detach(τ)) * c))
                return dr.detach(τ), dr.detach(c)
            dr.backward_from(-δρ * T_k * U * τ)               # ∂ρ/∂τ = −T U
            return dr.detach(τ), mi.Spectrum(0.0)

    @dr.syntax
    def _adjoint(self, ray, t0, u, active, δL, δρ, δα):
        """Adjoint: replay recording T_k, then march back to front with suffix R and U."""
        n_steps = self.n_steps
        n_rays = dr.width(ray.o)
        base = dr.arange(mi.UInt32, n_rays) * n_steps
        Ts = dr.zeros(mi.Float, n_rays * n_steps)
        dr.make_opaque(Ts)

        # Section 1: replay front to back, recording the transmittance before each segment.
        # Only a positive threshold cuts the ray short: with ε = 0 the gradient at an opaque
        # sample needs the suffix products U and R of the samples behind it (module docstring).
        ε = self.termination
        k = mi.UInt32(0)
        T = mi.Float(1.0)
        replay = mi.Bool(active)
        while replay:
            dr.scatter(Ts, T, base + k)
            p, s = self._segment(ray, t0, u, k)
            τ, _ = self._lookup(p, s, colour=False)
            T *= τ
            k += 1
            replay &= (k < n_steps) & ((T > ε) | (ε == 0.0))

        # Section 2: back to front, accumulating suffix radiance R and suffix transmittance U
        R = mi.Spectrum(0.0)
        U = mi.Float(1.0)
        back = mi.Bool(active) & (k > 0)
        while back:
            k -= 1
            T_k = dr.gather(mi.Float, Ts, base + k)
            p, s = self._segment(ray, t0, u, k)
            τ, c = self._backpropagate(p, s, T_k, R, U, δL, δρ, δα)
            R = (1.0 - τ) * c + τ * R                         # stays 0 for VH/AO (c = 0)
            U *= τ
            back &= k > 0


mi.register_integrator(INTEGRATOR_NAME, lambda props: RayMarcher(props))
