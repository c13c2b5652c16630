"""Training data for learned denoisers: noisy/clean patch datasets (:mod:`.patches`), a thread-pool
batch loader (:mod:`.loader`), noise samplers (:mod:`.samplers`) and sRGB-to-raw unprocessing
(:mod:`.unprocess`)."""
