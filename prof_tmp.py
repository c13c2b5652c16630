import numpy as np, cProfile, pstats
from simcam.dataset.groundtruth import *
D='/work/shared/data/emva1288_ccd/images'
b=Burst.from_directory(D, pattern='b_s_*.png', white_level=4095)
cProfile.run('g=estimate_ground_truth(b)','/tmp/prof')
pstats.Stats('/tmp/prof').sort_stats('tottime').print_stats(12)
