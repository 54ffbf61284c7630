"""Test-wide settings."""

import torch

# The tests run many tiny tensor operations; one thread avoids thread start-up and, on a shared
# machine, the large slow-down of threads that wait for a busy core.
torch.set_num_threads(1)
