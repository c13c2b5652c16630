import numpy as np, time, sys, dataclasses
from simcam.dataset.groundtruth import *
for b1 in (1e-4, 1e-3):
  kw=dict(shape=(512,512), n=40, drift_px=3.0, flicker_sd=0.002, outliers={5:0.85}, hot_fraction=0.002, seed=1, beta1=b1, beta2=b1/100, cell=4.0)
  sb=SyntheticBurst(**kw); so=SyntheticBurst(**{**kw,'clip':False})
  burst=Burst.from_arrays([sb.frame(i) for i in range(sb.n)], cfa="RGGB")
  oburst=Burst.from_arrays([so.frame(i) for i in range(sb.n)], cfa="RGGB", clip_low=-np.inf, clip_high=np.inf)
  dark=Burst.from_arrays([sb.dark(i) for i in range(20)], cfa="RGGB")
  out={}
  for name,cfg,bb in [('wls-local',GroundTruthConfig(),burst),('wls-global',GroundTruthConfig(alignment='global'),burst),('mean-local',GroundTruthConfig(method='mean'),burst),('mle-local',GroundTruthConfig(method='mle'),burst),('oracle',GroundTruthConfig(method='mean'),oburst)]:
    t=time.time(); g=estimate_ground_truth(bb, dark=dark, config=cfg); el=time.time()-t
    kept=[i for i in range(sb.n) if i not in [d['index'] for d in g.report['dropped']]]
    truth=sb.truth(g.reference)*sb.gains[kept].mean()
    out[name]=(g,truth)
  clipped=out['wls-local'][0].n_used < out['wls-local'][0].report['frames_used']
  m=~out['wls-local'][0].defects
  print('beta1',b1,'clipped px',(clipped&m).sum())
  for name,(g,truth) in out.items():
    e=g.gt-truth
    print(f"  {name:11s} ref {g.reference} drop {[d['index'] for d in g.report['dropped']]} mse {np.mean(e[m]**2)*1e6:.3f} clip {np.mean(e[m&clipped]**2)*1e6:.3f} shift {g.report['alignment']['max_shift_px']:.2f}")
