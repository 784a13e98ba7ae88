import torch

# Tiny models gain nothing from intra-op threads, and on a busy machine they lose a lot to them.
torch.set_num_threads(1)
