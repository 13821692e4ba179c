"""A small ACT policy for PushT made with LeRobot's own classes and saved as lerobot-eval loads one.

    python tests/lerobot/tiny_policy.py OUT_DIR [--image-size 96]

Random weights (torch.manual_seed), no pretrained backbone: nothing is downloaded. Its features
are LeRobot's pusht ones (observation.image 96 x 96 by default, observation.state and action of 2),
and its processors normalise with fixed PushT statistics (pixels of a 512-pixel frame), so
`lerobot-eval --policy.path=OUT_DIR` runs it as it runs a trained checkpoint.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def make_tiny_policy(out: Path, image_size: int = 96, device: str = "cpu", seed: int = 0) -> Path:
    import torch
    from lerobot.configs import FeatureType, PolicyFeature
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.act.modeling_act import ACTPolicy
    from lerobot.policies.factory import make_pre_post_processors

    torch.manual_seed(seed)
    cfg = ACTConfig(
        device=device, push_to_hub=False, pretrained_backbone_weights=None, chunk_size=8, n_action_steps=8,
        dim_model=32, n_heads=2, dim_feedforward=64, n_encoder_layers=1, n_decoder_layers=1, use_vae=False,
        input_features={
            "observation.image": PolicyFeature(type=FeatureType.VISUAL, shape=(3, image_size, image_size)),
            "observation.state": PolicyFeature(type=FeatureType.STATE, shape=(2,)),
        },
        output_features={"action": PolicyFeature(type=FeatureType.ACTION, shape=(2,))},
    )
    policy = ACTPolicy(cfg)
    stats = {
        "observation.image": {"mean": torch.full((3, 1, 1), 0.8), "std": torch.full((3, 1, 1), 0.3)},
        "observation.state": {"mean": torch.tensor([256.0, 256.0]), "std": torch.tensor([120.0, 120.0])},
        "action": {"mean": torch.tensor([256.0, 256.0]), "std": torch.tensor([120.0, 120.0])},
    }
    pre, post = make_pre_post_processors(cfg, dataset_stats=stats)
    out = Path(out)
    policy.save_pretrained(out)
    pre.save_pretrained(out)
    post.save_pretrained(out)
    return out


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", type=Path)
    p.add_argument("--image-size", type=int, default=96)
    p.add_argument("--device", default="cpu")
    a = p.parse_args()
    print(make_tiny_policy(a.out, a.image_size, a.device))
