"""Tests of analysis.planning.power: the vectorised test equals paired_wilcoxon, power agrees with a direct Monte Carlo.

The vectorised engine must reproduce :func:`analysis.stats.wilcoxon.paired_wilcoxon`
bit for bit on every resampled study (same p-value, same method), ties,
zeros, missing and infinite values included; then, on populations whose
power is known by direct simulation, the resampled estimate must agree within
its Monte Carlo interval, and with no effect the two-sided rejection rate must
be α and the directional one (a rejection on the pool's side) α/2.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats as sps

import foundation.resources
from analysis.planning.paired_pool import PairedPool, pool_from_trials
from analysis.planning.power import (
    FAMILY_ANY,
    POWER_CSV_COLUMNS,
    PowerError,
    estimate_power,
    monte_carlo_interval,
    resample_indices,
)
from analysis.planning.power_plan import smallest_n, summary_text
from analysis.reading.metrics import MetricOptions
from analysis.stats.holm import holm
from analysis.stats.resampled_wilcoxon import METHOD_NAMES, resampled_p_values
from analysis.stats.wilcoxon import paired_wilcoxon

zero_methods = st.sampled_from(["wilcox", "pratt", "zsplit"])


def _reference(off, on, idx, zero_method):
    """paired_wilcoxon on every row of idx: (p or NaN, method name)."""
    out = []
    for rows in idx:
        res = paired_wilcoxon(off[rows], on[rows], zero_method=zero_method)
        out.append((res.p_value if res.computable else math.nan, res.method if res.computable else ""))
    return out


@st.composite
def pools(draw):
    """A pool whose values make ties and zeros frequent, with rounding traps, NaN and the odd infinity."""
    size = draw(st.integers(1, 25))
    kind = draw(st.sampled_from(["tenths", "halves", "spread"]))
    if kind == "tenths":  # success rates: ON − OFF such as 0.7 − 0.6 only tie after rounding
        off = np.array(draw(st.lists(st.integers(0, 10), min_size=size, max_size=size))) / 10.0
        on = np.array(draw(st.lists(st.integers(0, 10), min_size=size, max_size=size))) / 10.0
    elif kind == "halves":
        off = np.array(draw(st.lists(st.integers(0, 20), min_size=size, max_size=size))) * 0.5
        on = off + np.array(draw(st.lists(st.integers(-6, 6), min_size=size, max_size=size))) * 0.5
    else:  # mostly distinct magnitudes: the exact branch
        off = np.array(draw(st.lists(st.floats(0, 10, allow_subnormal=False), min_size=size, max_size=size)))
        on = np.array(draw(st.lists(st.floats(0, 10, allow_subnormal=False), min_size=size, max_size=size)))
    for arr in (off, on):
        for i in draw(st.lists(st.integers(0, size - 1), max_size=3)):
            arr[i] = math.nan
    if draw(st.integers(0, 19)) == 0:
        off[draw(st.integers(0, size - 1))] = math.inf
    return off, on


@settings(max_examples=300)
@given(pools(), zero_methods, st.integers(1, 6), st.integers(1, 60), st.booleans(), st.integers(0, 2**32 - 1))
def test_vectorised_test_equals_paired_wilcoxon(pool, zero_method, resamples, n, replace, seed):
    off, on = pool
    rng = np.random.default_rng(seed)
    if replace:
        idx = rng.integers(0, off.size, size=(resamples, n))
    else:  # distinct members: untied studies reach the exact branch
        n = min(n, off.size)
        idx = np.stack([rng.permutation(off.size)[:n] for _ in range(resamples)])
    p, method = resampled_p_values(off, on, idx, zero_method=zero_method)
    for r, (p_ref, m_ref) in enumerate(_reference(off, on, idx, zero_method)):
        assert (math.isnan(p[r]) and math.isnan(p_ref)) or p[r] == p_ref, (r, p[r], p_ref, m_ref)
        assert METHOD_NAMES[method[r]] == m_ref


def test_every_method_branch_is_exercised_and_equal():
    """One deterministic block that hits exact, permutation, normal and not-computable rows at once."""
    rng = np.random.default_rng(7)
    off = np.round(rng.uniform(0, 1, 40), 1)
    on = np.round(off + rng.normal(-0.1, 0.15, 40), 1)
    on[3] = np.nan
    cont_off, cont_on = rng.normal(0, 1, 200), rng.normal(0.2, 1, 200)
    for o, n_, zm in ((off, 8, "wilcox"), (off, 30, "pratt"), (off, 60, "zsplit"), (cont_off, 20, "wilcox"),
                      (cont_off, 1, "wilcox")):
        a, b = (o, on) if o is off else (cont_off, cont_on)
        idx = rng.integers(0, a.size, size=(40, n_))
        p, method = resampled_p_values(a, b, idx, zero_method=zm)
        ref = _reference(a, b, idx, zm)
        assert [METHOD_NAMES[m] for m in method] == [m for _, m in ref]
        assert np.array_equal(p, np.array([x for x, _ in ref]), equal_nan=True)
    all_zero = np.full(6, 0.5)
    p, method = resampled_p_values(all_zero, all_zero, np.zeros((3, 5), dtype=int))
    assert np.isnan(p).all() and (method == 0).all()


@given(st.lists(st.lists(st.one_of(st.floats(0, 1), st.just(math.nan)), min_size=4, max_size=4), min_size=1,
                max_size=30))
def test_holm_per_row_equals_holm_of_each_row(rows):
    p = np.array(rows)
    adj = holm(p, axis=1)
    for r in range(p.shape[0]):
        assert np.array_equal(adj[r], holm(p[r]), equal_nan=True)
    assert np.array_equal(holm(p.T, axis=0), adj.T, equal_nan=True)
    assert np.array_equal(holm(p), holm(p.ravel()).reshape(p.shape), equal_nan=True)  # default: one family


@pytest.mark.parametrize("k", [0, 1, 37, 1000, 1999, 2000])
def test_monte_carlo_interval_is_clopper_pearson(k):
    lo, hi = monte_carlo_interval(np.array([k]), 2000)
    ref = sps.binomtest(k, 2000).proportion_ci(0.95)
    assert lo[0] == pytest.approx(ref.low, abs=1e-12) and hi[0] == pytest.approx(ref.high, abs=1e-12)


# -- agreement with a direct Monte Carlo of a known population -------------------------------------------
def _pool(off: np.ndarray, on: np.ndarray) -> PairedPool:
    """A one-metric-per-slot pool: the same pairs in all four metric slots, overall only."""
    codes = tuple(f"S{i}" for i in range(off.size))
    return PairedPool(codes, ("overall",), ("success_rate", "tct_s", "rmse_n", "max_ae_n"),
                      np.tile(off, (1, 4, 1)), np.tile(on, (1, 4, 1)), "a known population")


def _agree(row: pd.Series, direct_rate: float, direct_m: int, prefix: str = "") -> None:
    """The two Monte Carlo estimates agree: each 95 % interval reaches the other's point estimate's interval."""
    lo, hi = monte_carlo_interval(np.array([round(direct_rate * direct_m)]), direct_m)
    low, high = row[f"{prefix}ci_low"], row[f"{prefix}ci_high"]
    assert low <= hi[0] and lo[0] <= high, (prefix, row["power"], low, high, direct_rate)


def _side(d: np.ndarray, zero_method: str = "wilcox") -> np.ndarray:
    """Direction of each row's effect, from first principles: W⁺ against its null mean over the non-zero pairs.

    Zeros are dropped before ranking ("wilcox") or ranked with the rest ("pratt", "zsplit", whose zero ranks
    split evenly and so do not move W⁺ against its mean).
    """
    out = np.empty(len(d), dtype=int)
    for i, row in enumerate(d):
        if zero_method == "wilcox":
            row = row[row != 0]
        ranks = sps.rankdata(np.abs(row))
        out[i] = np.sign(ranks[row > 0].sum() - ranks[row != 0].sum() / 2)
    return out


@settings(max_examples=60, deadline=None)
@given(pools(), zero_methods, st.integers(0, 2**31 - 1))
def test_the_side_of_each_resample_is_that_of_its_signed_rank_statistic(pool, zero_method, seed):
    off, on = pool
    good = np.isfinite(off) & np.isfinite(on)
    off, on = off[good], on[good]
    if off.size == 0:
        return
    idx = np.random.default_rng(seed).integers(0, off.size, (20, min(off.size, 9) + 1))
    _, _, side = resampled_p_values(off, on, idx, zero_method=zero_method, sides=True)
    d = np.round(on - off, 10)[idx]
    assert np.array_equal(side, _side(d, zero_method))


def test_power_of_a_continuous_population_matches_direct_simulation():
    rng = np.random.default_rng(2024)
    # d = ON − OFF ~ N(−0.5, 1): haptics lower the error by half a standard deviation
    off = rng.normal(1.0, 0.3, 20_000)
    on = off + rng.normal(-0.5, 1.0, off.size) * 0.3
    result = estimate_power(_pool(off, on), (12, 30), resamples=4000, seed=3)
    direct_m = 20_000
    for n in (12, 30):
        d = rng.normal(-0.5, 1.0, (direct_m, n)) * 0.3  # fresh studies from the population itself
        reject = sps.wilcoxon(d, axis=1).pvalue < 0.05  # exact test: no ties in continuous data
        row = result.frame[(result.frame["metric"] == "rmse_n") & (result.frame["n"] == n)].iloc[0]
        assert row["direction"] == "on_lower"
        _agree(row, float((reject & (_side(d) < 0)).mean()), direct_m)  # detected, and lower with haptics
        _agree(row, float(reject.mean()), direct_m, "two_sided_")
        assert 0.1 < row["power"] < 0.95  # a power that can be told apart from 0 and 1


def test_power_of_a_discrete_population_matches_direct_simulation():
    """Success counts out of 10: ties and zeros everywhere, the permutation and normal branches."""
    def draw(rng, size):
        skill = rng.normal(0.0, 0.7, size)
        off = rng.binomial(10, 1 / (1 + np.exp(-(skill - 1.0)))) / 10.0
        on = rng.binomial(10, 1 / (1 + np.exp(-(skill - 0.5)))) / 10.0
        return off, on

    rng = np.random.default_rng(99)
    result = estimate_power(_pool(*draw(rng, 20_000)), (10, 16), resamples=2000, seed=5)
    direct_m = 800  # the two Monte Carlo intervals' widths are in _agree: fewer draws, wider, still one rate
    for n in (10, 16):
        hits = hits_up = 0
        for _ in range(direct_m):
            off, on = draw(rng, n)
            res = paired_wilcoxon(off, on)
            significant = bool(res.computable and res.p_value < 0.05)
            hits += significant
            hits_up += significant and _side(np.round(on - off, 10)[None, :])[0] > 0
        row = result.frame[(result.frame["metric"] == "success_rate") & (result.frame["n"] == n)].iloc[0]
        assert row["permutation"] + row["approx"] > 0.9 * row["resamples"] and row["direction"] == "on_higher"
        _agree(row, hits_up / direct_m, direct_m)
        _agree(row, hits / direct_m, direct_m, "two_sided_")


def test_no_effect_rejects_at_rate_alpha():
    rng = np.random.default_rng(11)
    off = rng.normal(5.0, 1.0, 20_000)
    on = rng.normal(5.0, 1.0, 20_000)  # ON and OFF from the same distribution
    result = estimate_power(_pool(off, on), (6, 20, 30), resamples=4000, seed=1)
    rows = result.frame[result.frame["metric"] == "rmse_n"].set_index("n")
    for n in (20, 30):
        assert rows.at[n, "two_sided_ci_low"] <= 0.05 <= rows.at[n, "two_sided_ci_high"], rows.loc[n]
        assert rows.at[n, "ci_low"] <= 0.025 <= rows.at[n, "ci_high"], rows.loc[n]  # one side of it: α/2
    # at n = 6 the exact test can only reach p = 2/64 < 0.05 for all-positive or all-negative studies: 2/64 of
    # them, and half of those lie on the pool's side
    assert rows.at[6, "two_sided_ci_low"] <= 2 / 64 <= rows.at[6, "two_sided_ci_high"]
    assert rows.at[6, "ci_low"] <= 1 / 64 <= rows.at[6, "ci_high"]
    fam = result.frame[(result.frame["metric"] == FAMILY_ANY) & (result.frame["n"] == 30)].iloc[0]
    assert fam["power"] <= 0.05 + 0.01  # Holm keeps the family-wise error at α (four identical tests here)


# -- the pool and the edges ---------------------------------------------------------------------------
def _trials(participants: int, seed: int = 0, success_off: float = 0.3, success_on: float = 0.6) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    rows = []
    for p in range(participants):
        for label, force in (("GENTLE", 0.6), ("FIRM", 1.2)):
            for mode in ("off", "on"):
                for _ in range(5):
                    ok = bool(rng.random() < (success_on if mode == "on" else success_off))
                    tct = round(float(rng.uniform(2, 10)), 3) if ok else math.nan
                    rmse = float(rng.lognormal(math.log(0.8 if mode == "off" else 0.55), 0.3))
                    rows.append(dict(participant_code=f"P{p:02d}", target_label=label, target_force_n=force,
                                     haptic_mode=mode, success=ok, tct_s=tct, rmse_n=rmse, max_ae_n=2.5 * rmse,
                                     time_in_band_s=1.0, peak_force_n=force, tct_censored_s=tct if ok else 12.0))
    return pd.DataFrame(rows)


def test_pool_uses_the_reports_aggregation():
    from analysis.stats.aggregate import per_participant

    trials = _trials(6)
    pool = pool_from_trials(trials, MetricOptions(tct_policy="censored"))
    assert pool.scopes == ("overall", "GENTLE", "FIRM") and pool.participants == tuple(f"P{i:02d}" for i in range(6))
    ref = per_participant(trials, MetricOptions(tct_policy="censored")).set_index(["participant_code", "haptic_mode"])
    for m, metric in enumerate(pool.metrics):
        assert np.array_equal(pool.off[0, m], ref.xs("off", level=1).loc[list(pool.participants), metric].to_numpy())
        assert np.array_equal(pool.on[0, m], ref.xs("on", level=1).loc[list(pool.participants), metric].to_numpy())


def test_estimate_writes_the_promised_columns_and_is_reproducible():
    pool = pool_from_trials(_trials(8))
    a = estimate_power(pool, (6, 10), resamples=300, seed=4)
    b = estimate_power(pool, (10, 6, 10), resamples=300, seed=4)
    c = estimate_power(pool, (10,), resamples=300, seed=5)
    assert list(a.frame.columns[: len(POWER_CSV_COLUMNS)]) == list(POWER_CSV_COLUMNS)
    pd.testing.assert_frame_equal(a.frame, b.frame)  # same seed, same numbers; the n list is a set
    only10 = estimate_power(pool, (10,), resamples=300, seed=4).frame.reset_index(drop=True)
    pd.testing.assert_frame_equal(a.frame[a.frame["n"] == 10].reset_index(drop=True), only10)  # n-independent draws
    assert not a.frame[a.frame["n"] == 10]["rejections"].reset_index(drop=True).equals(
        c.frame["rejections"].reset_index(drop=True))
    f = a.frame
    assert set(f["metric"]) == {"success_rate", "tct_s", "rmse_n", "max_ae_n", "all_four_holm", FAMILY_ANY}
    assert ((f["ci_low"] <= f["power"]) & (f["power"] <= f["ci_high"])).all()
    assert (f["power_holm"] <= f["power"]).all()  # Holm never rejects what the test alone does not
    tests = f[f["metric"].isin(pool.metrics)]
    assert (tests["power"] <= tests["power_two_sided"]).all()  # directional: a subset of the rejections
    assert set(tests["direction"]) <= {"on_higher", "on_lower"} and f[~f["metric"].isin(pool.metrics)][
        "power_two_sided"].isna().all()
    assert (f[f["metric"] != FAMILY_ANY]["exact"] + f["permutation"] + f["approx"] + f["not_computable"]
            == f["resamples"])[f["metric"].isin(pool.metrics)].all()


def test_undefined_tct_is_left_out_and_said():
    trials = _trials(10, success_off=0.12, seed=3)  # several participants never succeed with haptics OFF
    pool = pool_from_trials(trials, MetricOptions(tct_policy="successful"))  # the text's reading: undefined there
    undefined = int(np.isnan(pool.off[0, 1]).sum())
    assert undefined > 0
    result = estimate_power(pool, (20,), resamples=500)
    row = result.frame[(result.frame["metric"] == "tct_s") & (result.frame["scope"] == "overall")].iloc[0]
    assert row["mean_pairs"] == pytest.approx(20 * (1 - undefined / 10), rel=0.05)
    assert any(f"undefined for {undefined} of 10 participants" in n for n in result.notes)


def test_all_zero_differences_give_power_zero_with_a_note():
    trials = _trials(6)
    off_rmse = trials.loc[trials["haptic_mode"] == "off", "rmse_n"].to_numpy()
    trials.loc[trials["haptic_mode"] == "on", "rmse_n"] = off_rmse
    result = estimate_power(pool_from_trials(trials), (6, 12), resamples=200)
    rows = result.frame[(result.frame["metric"] == "rmse_n") & (result.frame["scope"] == "overall")]
    assert (rows["power"] == 0).all() and (rows["not_computable"] == rows["resamples"]).all()
    assert any("RMSE (N): every participant has ON = OFF" in n for n in result.notes)
    assert smallest_n(result.frame, "overall", "rmse_n", 0.8) is None
    assert "> 12 (0%)" in summary_text(result)


def test_a_rejection_against_the_pools_direction_is_not_power():
    """A pool whose effect is weak and mixed: resampled studies sometimes reject the wrong way round."""
    rng = np.random.default_rng(8)
    off = rng.normal(0.0, 1.0, 12)
    on = off + rng.normal(0.15, 1.0, 12)
    result = estimate_power(_pool(off, on), (6, 10, 16), resamples=3000, seed=2)
    rows = result.frame[result.frame["metric"] == "rmse_n"]
    wrong_way = rows["rejections_two_sided"] - rows["rejections"]
    assert (wrong_way > 0).any() and (wrong_way >= 0).all()
    # and they are exactly the two-sided rejections whose side is not the pool's
    pool_side = 1 if rows["direction"].iloc[0] == "on_higher" else -1
    idx = resample_indices(2, 10, 3000, 12)
    p, _, side = resampled_p_values(off, on, idx, sides=True)
    assert int(((p < 0.05) & (side == pool_side)).sum()) == int(rows[rows["n"] == 10]["rejections"].iloc[0])


def test_a_pool_of_one_sign_is_said_to_overstate_power():
    trials = _trials(8)
    result = estimate_power(pool_from_trials(trials), (6,), resamples=50)
    pool = pool_from_trials(trials)
    d = pool.on[0, 2] - pool.off[0, 2]
    assert (d < 0).all()  # RMSE lower with haptics for every one of these participants
    one_sign = [n for n in result.notes if n.startswith("every participant of the pool has the same sign")]
    assert len(one_sign) == 1 and "RMSE (N) ON < OFF" in one_sign[0] and "overstates the power" in one_sign[0]


def test_a_pilot_of_three_is_refused_in_words():
    with pytest.raises(PowerError, match="has 3 participants with both haptic modes: at least 4 are needed"):
        estimate_power(pool_from_trials(_trials(3)), (10,), resamples=10)


@pytest.mark.parametrize(("kwargs", "message"), [
    (dict(n_values=(1,)), "n = 1: each study size must be a whole number from 2 to 10000"),
    (dict(resamples=0), "resamples = 0: must be a whole number from 1 to 1000000"),
    (dict(alpha=1.5), "alpha = 1.5: must be a number with 0 < alpha < 1"),
    (dict(zero_method="none"), "zero_method = 'none': allowed are wilcox, pratt, zsplit"),
])
def test_malformed_requests_are_refused(kwargs, message):
    with pytest.raises(PowerError, match=message.replace("(", r"\(").replace(")", r"\)")):
        estimate_power(pool_from_trials(_trials(5)), **{"n_values": (10,), **kwargs})


def test_smallest_n_needs_every_larger_n_to_reach_the_target():
    f = pd.DataFrame({"scope": "overall", "metric": "m", "n": [6, 8, 10, 12], "power": [0.5, 0.82, 0.79, 0.9],
                      "power_holm": [0.1, 0.2, 0.85, 0.95]})
    assert smallest_n(f, "overall", "m", 0.8) == 12  # 8 reaches it, but 10 falls back below
    assert smallest_n(f, "overall", "m", 0.8, holm_adjusted=True) == 10
    assert smallest_n(f, "overall", "m", 0.99) is None


def test_resample_indices_depend_on_seed_and_n_only():
    a = resample_indices(3, 10, 50, 7)
    assert a.shape == (50, 10) and a.min() >= 0 and a.max() < 7
    assert np.array_equal(a, resample_indices(3, 10, 50, 7))
    assert not np.array_equal(a, resample_indices(4, 10, 50, 7))


# -- limits that fit the machine (issue 22) -----------------------------------------------------------------------
def test_chunked_resampling_gives_the_same_numbers_bit_for_bit():
    pool = pool_from_trials(_trials(8))
    whole = estimate_power(pool, (6, 11), resamples=333, seed=4)
    seen = []
    chunked = estimate_power(pool, (6, 11), resamples=333, seed=4, chunk_bytes=1000,
                             progress=lambda done, total: seen.append((done, total)))
    pd.testing.assert_frame_equal(whole.frame, chunked.frame, check_exact=True)
    assert len(seen) > 20 and seen[-1] == (333 * 17, 333 * 17) and seen == sorted(seen)


def test_memory_does_not_grow_with_the_resamples():
    import tracemalloc

    from analysis.planning.power import memory_needed

    pool = pool_from_trials(_trials(8))
    tracemalloc.start()
    try:
        estimate_power(pool, (200,), resamples=4000, chunk_bytes=4 << 20)  # 800,000 draws; 77 MB at once
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 16 << 20
    assert memory_needed((200,), 4000, 8, 4 << 20) == memory_needed((200,), 10**6, 8, 4 << 20)


def test_a_request_the_machine_cannot_hold_is_refused_in_one_line(monkeypatch):

    monkeypatch.setattr(foundation.resources, "available_memory_bytes", lambda: 8 << 20)
    pool = pool_from_trials(_trials(8))
    with pytest.raises(PowerError) as err:
        estimate_power(pool, (6, 10_000), resamples=10)
    assert str(err.value) == ("power: resampling studies of up to 10000 participants needs about 17.8 MiB of memory; "
                              "this "
                              "machine has 8.0 MiB available; ask for smaller --n values (memory grows with n; "
                              "--resamples costs time only)")
