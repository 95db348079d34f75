"""Toy measurement of the fine-tuning options of a pretrained backbone (models/cone_detector.md).

MobileNetV2-p from ImageNet, 24 AdamW steps (lr 0.002, batch 8) on 48 synthetic cone images of
tests/synthetic_cones.py, the trainer's own param groups (build_optimizer) and freezing
(set_backbone_mode, 8 steps = one "epoch"); printed: loss on 16 held-out images, two seeds.
A toy (flat drawn cones, seconds of training), not the real frames: it says which option
does not hurt at the start of a run, not what pays at convergence.

    .venv/bin/python docs/experiments/finetune_recipe_toy.py    # from the repository root, ~2 min
"""
import sys, torch, numpy as np
sys.path.insert(0, 'tests')
from test_pretrained import _cone_batch
from cone_perception.model import ConeYOLO, model_config
from cone_perception.model.loss import DetectionLoss
from cone_perception.model.pretrained import load_imagenet
from cone_perception.train.trainer import TrainConfig, build_optimizer, set_backbone_mode


def main() -> None:
    torch.set_num_threads(1)
    train=[_cone_batch(100+k,8) for k in range(6)]; held=_cone_batch(999,16)
    variants={'plain':{}, 'backbone_lr 0.1':{'backbone_lr':0.1}, 'backbone_lr 0.3':{'backbone_lr':0.3}, 'freeze_bn':{'freeze_bn':True}, 'frozen first 8 steps':{'freeze_backbone':1}}
    steps, per_epoch = 24, 8
    for seed in (0,1):
      for name,kw in variants.items():
        torch.manual_seed(seed)
        m=ConeYOLO(model_config('mobilenet_v2-p')); load_imagenet(m.backbone)
        cfg=TrainConfig(data='',out='',**kw)
        crit=DetectionLoss(m.cfg.num_classes,m.cfg.reg_max,m.strides); opt=build_optimizer(m,cfg)
        for s in range(steps):
            m.train(); set_backbone_mode(m,cfg,s//per_epoch)
            for g in opt.param_groups: g['lr']=2e-3*g.get('lr_mult',1.0)
            x,t=train[s%6]; loss,_=crit(m(x),t); opt.zero_grad(); loss.backward(); opt.step()
        m.train(); set_backbone_mode(m,cfg,steps//per_epoch)  # frozen BN stays frozen when measured
        with torch.no_grad(): vl=crit(m.forward_raw(held[0]),held[1])[0].item()/16
        print(seed, name, round(vl,3), flush=True)


if __name__ == "__main__":
    if len(sys.argv) > 1:  # -h, --help, or anything: it takes no arguments
        print(__doc__)
        sys.exit(0)
    main()
