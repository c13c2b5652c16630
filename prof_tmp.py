import numpy as np, time
from simcam.dataset.groundtruth.alignment import *
rng=np.random.default_rng(0)
from scipy import ndimage
H,W=3000,4000
ref=np.clip(ndimage.gaussian_filter(rng.random((H,W),dtype=np.float32),2)*3-1,0,1).astype(np.float32)
mov=ref+0.01*rng.standard_normal((H,W),dtype=np.float32)
T={}
t=time.time(); R=prepare_reference(ref,'RGGB'); T['prep']=time.time()-t
t=time.time(); lm,sh,ok=local_shifts(R,mov); T['shifts']=time.time()-t
t=time.time(); keep=reject_outliers(R.grid,sh,ok); T['rej']=time.time()-t
t=time.time(); f=dense_field(lm[keep] if keep.any() else lm, (sh[keep] if keep.any() else sh)+0.3, (H,W),'RGGB'); T['field']=time.time()-t
t=time.time(); w=warp(mov,f,'RGGB',order=3); T['warp3']=time.time()-t
t=time.time(); w=warp(mov,f,'RGGB',order=1); T['warp1']=time.time()-t
t=time.time(); w=warp((mov>0.99).astype(np.int8),f,'RGGB',order=0); T['warp0']=time.time()-t
print({k:round(v,2) for k,v in T.items()}, len(lm), keep.sum())
import cProfile, pstats
cProfile.run('local_shifts(R,mov)','/tmp/p2')
pstats.Stats('/tmp/p2').sort_stats('tottime').print_stats(8)
