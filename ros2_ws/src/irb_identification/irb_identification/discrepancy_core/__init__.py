"""Model-discrepancy workflow (DESIGN.md §8): residuals, effect library, selection, report.

Plain modules (numpy/scipy, no rclpy): ``bagdata`` (bags <-> arrays), ``excitation`` (the
motions, recorded offline through irb_control's closed loop), ``residuals`` (nominal model on
the measured motion), ``library`` (candidate effects as regressors), ``selection`` (BIC,
block bootstrap, decision), ``workflow`` (the whole run), ``report`` (JSON, Markdown, PNG).
"""
