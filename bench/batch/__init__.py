"""The batch engine: many lockstep sessions of the mock rig and the compiled FOC in one compiled loop
(`bench.batch.engine`, over the numba kernel `bench.batch.kernel`)."""
