"""Backscatter laws other than Mitsuba's `diffuse` as one Mitsuba BSDF: radiance ~ cos^power(incidence).

Mitsuba's `diffuse` BSDF gives radiance albedo / pi * I cos(theta) / d^2 per spot: the
cosine of incidence once. Lambert's law for acoustic backscatter, sigma = mu sin^2(grazing)
= mu cos^2(theta), has it twice (the facet's projected area towards the source and towards
the receiver, which for a sonar are the same direction). This BSDF evaluates
albedo / pi * cos^2(theta_light), so a tilted facet facing the array brightens more and a
facet turned away darkens more than with `diffuse`. The camera direction does not enter:
the camera only looks at the floor, it is not the receiver. Its `reflectance` texture
traverses like diffuse's (`reflectance.value`), so scene updates and AD see the same key.

`backscatter = "rough"` (power 0.5, geometry.COS_POWER) is the other way round: a surface rough at
scales far below a pixel (rock, rubble) turns facets towards the array whatever the mean
slope, so its echo depends little on incidence and a boulder's top, lit at a few degrees'
grazing, stays bright instead of fading as cos(incidence).
"""
from __future__ import annotations

PLUGIN = "cos_power"
_registered: set[int] = set()


def register(mi, dr) -> None:
    """Register the plugin with the current variant (once per process)."""
    if id(mi.BSDF) in _registered:
        return

    class CosPower(mi.BSDF):
        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.reflectance = props["reflectance"]
            self.power = props["power"]
            flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            self.m_components = [flags]
            self.m_flags = flags

        def _value(self, si, wo, active):
            cos_i, cos_o = mi.Frame3f.cos_theta(si.wi), mi.Frame3f.cos_theta(wo)
            ok = active & (cos_i > 0) & (cos_o > 0)
            return ok, self.reflectance.eval_1(si, ok) * dr.inv_pi * dr.power(cos_o, self.power)

        def sample(self, ctx, si, sample1, sample2, active=True):
            bs = mi.BSDFSample3f()
            bs.wo = mi.warp.square_to_cosine_hemisphere(sample2)
            bs.pdf = mi.warp.square_to_cosine_hemisphere_pdf(bs.wo)
            bs.eta = 1.0
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
            bs.sampled_component = mi.UInt32(0)
            ok, value = self._value(si, bs.wo, active)
            return bs, dr.select(ok & (bs.pdf > 0), value / bs.pdf, 0.0)

        def eval(self, ctx, si, wo, active=True):
            ok, value = self._value(si, wo, active)
            return dr.select(ok, value, 0.0)

        def pdf(self, ctx, si, wo, active=True):
            ok = active & (mi.Frame3f.cos_theta(si.wi) > 0) & (mi.Frame3f.cos_theta(wo) > 0)
            return dr.select(ok, mi.warp.square_to_cosine_hemisphere_pdf(wo), 0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

        def traverse(self, callback):
            callback.put("reflectance", self.reflectance, mi.ParamFlags.Differentiable)

        def parameters_changed(self, keys):
            pass

        def to_string(self):
            return f"CosPower[power={self.power}, reflectance={self.reflectance}]"

    mi.register_bsdf(PLUGIN, lambda props: CosPower(props))
    _registered.add(id(mi.BSDF))


def bsdf_dict(albedo: float, cos_power: float) -> dict:
    """load_dict entry of a surface with `albedo` and cos(incidence)^cos_power radiance."""
    reflectance = {"type": "uniform", "value": albedo}
    if cos_power == 1:
        return {"type": "diffuse", "reflectance": reflectance}
    return {"type": PLUGIN, "power": float(cos_power), "reflectance": reflectance}
