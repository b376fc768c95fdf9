"""Nearest ×2 upsampling and a 3×3 conv computed at the low resolution: the generator's up stages."""
from __future__ import annotations

import pytest
import torch
import torch.nn as nn

from sasmi.gan.upsample import NearestUpConv, fold_upsampling


@pytest.mark.parametrize("padding_mode", ["reflect", "replicate"])
@pytest.mark.parametrize("channels_last", [False, True])
def test_the_folded_stage_is_the_upsampling_and_the_conv(padding_mode, channels_last):
    torch.manual_seed(0)
    conv = nn.Conv2d(3, 5, 3, padding=1, padding_mode=padding_mode)
    x = torch.randn(2, 3, 6, 9)  # not square, odd width: every edge and phase
    if channels_last:
        x = x.contiguous(memory_format=torch.channels_last)
    expected = conv(nn.Upsample(scale_factor=2, mode="nearest")(x))
    got = NearestUpConv(conv)(x)
    assert got.shape == expected.shape == (2, 5, 12, 18)
    assert torch.allclose(got, expected, atol=1e-5)


def test_only_upsampling_conv_pairs_it_computes_are_folded_and_the_state_dict_is_kept():
    torch.manual_seed(0)
    up = lambda mode="nearest": nn.Upsample(scale_factor=2, mode=mode)  # noqa: E731
    net = nn.Sequential(up(), nn.Conv2d(2, 4, 3, padding=1, padding_mode="reflect"), nn.ReLU(),
                        up("bilinear"), nn.Conv2d(4, 4, 3, padding=1, padding_mode="reflect"),
                        up(), nn.Conv2d(4, 1, 3, padding=1))  # zero padding: not folded
    x = torch.randn(1, 2, 5, 4)
    state = {k: v.clone() for k, v in net.state_dict().items()}
    with torch.no_grad():
        expected = net(x)
        fold_upsampling(net)
        got = net(x)
    assert [type(m).__name__ for m in net] == ["Identity", "NearestUpConv", "ReLU", "Upsample", "Conv2d",
                                               "Upsample", "Conv2d"]
    assert torch.allclose(got, expected, atol=1e-5)
    assert net.state_dict().keys() == state.keys()
    assert all(torch.equal(v, state[k]) for k, v in net.state_dict().items())
    with torch.no_grad():
        assert torch.allclose(net[1].unfolded()(x), net[1](x), atol=1e-5)  # the plain layers back


def test_a_conv_it_cannot_compute_is_refused():
    with pytest.raises(ValueError, match="3×3"):
        NearestUpConv(nn.Conv2d(2, 2, 3, padding=1))  # zero padding: the phases would read zeros, not edges
