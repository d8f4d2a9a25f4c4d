

def test_ctrl_c_keeps_finished_runs(dp, tmp_path, monkeypatch):
    from mechdsl.sweep import runs, schedulers

    calls = []

    def interrupted(job, first, values):
        calls.append(first)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return runs.run_chunk(job, first, values)

    monkeypatch.setattr(schedulers, "run_chunk", interrupted)
    out = tmp_path / "part.nc"
    ds = dp.sweep(starts={"j1.phi": [0.5, 1.0, 1.5, 2.0]}, t_end=0.2, points=3, chunk_size=1, progress=False,
                  out=str(out))
    assert ds.attrs["interrupted"] == 1 and ds.attrs["n_finished"] == 2
    assert list(ds["success"].values) == [True, True, False, False]
    assert list(ds["cause"].values[2:]) == ["not run", "not run"]
    assert np.isfinite(ds["j1.phi"].values[:2]).all() and np.isnan(ds["j1.phi"].values[2:]).all()
    assert [p.name for p in tmp_path.iterdir()] == ["part.nc"]
    ds.close()


def test_vectorized_refused_for_a_dae_with_the_reason():
    m = mechdsl.load(mechdsl.__file__.rsplit("/src/", 1)[0] + "/models/four_bar.mech")
    with pytest.raises(UsageError, match="constraints"):
        m.sweep(params={m.parameter_names[0]: [1.0, 2.0]}, t_end=0.1, scheduler="vectorized")
