# Per-figure targets for the paper's figures (studies/figures.py). Include from the Makefile:
#     include studies/figures.mk
# then e.g. `make fig4a` writes $(OUT)/fig4a.h5, fig4a.png, fig4a_shape.png, fig4a.json.
FIGURE_NAMES = fig2a fig2b fig4a fig4b fig4c figS9 figS3

.PHONY: $(FIGURE_NAMES)
fig2a fig2b fig4a fig4b fig4c figS9 figS3: $(STAMP)  ## one figure of the paper each (studies/figures.py --only)
	@mkdir -p $(OUT)
	$(BIN)/python studies/figures.py --out $(OUT) --only $@ --jobs $(JOBS)
