import numpy as np, time
from simcam.dataset.groundtruth import *
import sys
CELL=float(sys.argv[1])
for b1,drift in ((2e-4,3.0),(5e-5,4.0),(2e-5,6.0)):
    sb = SyntheticBurst(shape=(384, 384), n=24, beta1=b1, beta2=b1/100, drift_px=drift, flicker_sd=0.002,
                        outliers={4: 0.85}, hot_fraction=0.002, cell=CELL, seed=7)
    frames=[sb.frame(i) for i in range(sb.n)]; dark=Burst.from_arrays([sb.dark(i) for i in range(16)])
    res={}
    for nm,cfg in (('local',GroundTruthConfig()),('global',GroundTruthConfig(alignment='global')),('none',GroundTruthConfig(alignment='none'))):
        t=time.time(); g=estimate_ground_truth(Burst.from_arrays(frames), dark=dark, config=cfg)
        kept=[i for i in range(sb.n) if i not in [d['index'] for d in g.report['dropped']]]
        truth=sb.truth(g.reference)*sb.gains[kept].mean()
        res[nm]=np.mean((g.gt-truth)[~sb.hot]**2)
    naive=np.mean((np.mean(frames,0)-truth)[~sb.hot]**2)
    print(b1,drift,{k:f"{v:.3g}" for k,v in res.items()}, 'naive',f"{naive:.3g}", f"{time.time()-t:.1f}s")
