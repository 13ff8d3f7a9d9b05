# LandScape-gRPC. `make run` and `make test` install what they need on first use.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
GRPCURL_VERSION := v1.9.3
GRPCURL := .tools/bin/grpcurl
# make run CONFIG=cell.toml runs another cell; make certs HOSTS="cell1.lan 192.168.10.20"
CONFIG ?=
HOSTS ?=

.PHONY: help install run certs test test-fast lint proto bench clean tools clients clients-go \
	clients-ts

help:
	@echo "make run      install, then start the cell: a device server on 127.0.0.1:50051 with"
	@echo "              its simulated arm, the CRCL gateway on 64444, the web supervisor on"
	@echo "              8080 (when installed); CONFIG=file for another cell (landscape-cell)"
	@echo "make certs    a development CA, certificates (var/certs) and role tokens (var/tokens);"
	@echo "              HOSTS=\"names or addresses\" of the device servers' machines"
	@echo "make test     install (tools and clients too), then run every test"
	@echo "make test-fast  the edit-and-test loop: every test but the slow ones (browsers,"
	@echo "              other languages, cells of processes, real time, physics, fuzzing)"
	@echo "make lint     buf lint of proto/"
	@echo "make proto    regenerate the Python stubs from proto/"
	@echo "make bench    run every benchmark: one table, bench/results/latest.json (QUICK=1: short)"
	@echo "make tools    build grpcurl $(GRPCURL_VERSION) into .tools/bin, fetch NIST's CRCL client"
	@echo "              (make install fetches NIST's CRCL schemas into .tools/crcl-schemas)"
	@echo "make clients  build the Go and TypeScript example clients (clients/)"
	@echo "make clean    remove the virtualenv, generated stubs and caches"

# Editable install; setup.py generates the landscape.v1 stubs from proto/ on every build.
$(STAMP): pyproject.toml setup.py $(wildcard proto/landscape/v1/*.proto)
	@echo "installing into $(VENV) (a minute or two the first time)"
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	@$(PY) -m pip install -q --upgrade pip
	@# setuptools warns of every editable install of a layout like ours (a finder maps the
	@# folders into `landscape`): that one notice is filtered, nothing else
	@# (tests/test_packaging.py checks that the build warns of nothing else).
	@PYTHONWARNINGS="ignore:Editable installation" $(PY) -m pip install -q -e '.[dev]'
	@touch $@

# The web supervisor's page: npm packages as locked, then the Vite build the backend serves.
# Optional, like grpcurl: without npm the rest installs, and the cell runs without the web
# supervisor, saying why (its tests skip).
FRONTEND := supervisor_gui_web/frontend
NO_NPM := make: no npm on this machine, so the web supervisor's page is not built and the cell \
	runs without it (install Node.js and npm, then make install)
$(FRONTEND)/node_modules/.package-lock.json: $(FRONTEND)/package.json $(FRONTEND)/package-lock.json
	@if command -v npm >/dev/null; then \
	  echo "installing the web supervisor's npm packages (as package-lock.json says)"; \
	  cd $(FRONTEND) && npm ci --silent --no-audit --no-fund; \
	else echo "$(NO_NPM)"; fi
$(FRONTEND)/dist/index.html: $(FRONTEND)/node_modules/.package-lock.json $(FRONTEND)/index.html \
		$(FRONTEND)/vite.config.js $(wildcard $(FRONTEND)/src/*)
	@if command -v npm >/dev/null; then cd $(FRONTEND) && npm run --silent build; fi

# NIST's CRCL schemas, as crcl4java-base 1.8 on Maven Central carries them (the 2018 revision,
# which NIST's Java client speaks): the CRCL gateway validates every document against them and
# its tests check every status. Optional, like grpcurl: without Java and Maven the gateway
# says at start that it validates against none, and the schema tests skip, naming this step.
CRCL_SCHEMAS := .tools/crcl-schemas/CRCLStatus.xsd
$(CRCL_SCHEMAS): | $(STAMP)
	@if command -v mvn >/dev/null && command -v java >/dev/null; then \
	  echo "installing NIST's CRCL schemas (crcl4java-base 1.8) into $(@D)"; \
	  mvn -q -B dependency:copy -Dartifact=com.github.wshackle:crcl4java-base:1.8:jar \
	    -DoutputDirectory=$(CURDIR)/.tools/maven && \
	  $(PY) -c 'import sys, zipfile; jar = zipfile.ZipFile(sys.argv[1]); \
	    [jar.extract(n, sys.argv[2]) for n in jar.namelist() if n.endswith(".xsd")]' \
	    .tools/maven/crcl4java-base-1.8.jar $(@D); \
	else echo "make: no Java and Maven here, so no CRCL schemas: the gateway validates" \
	  "documents with its own parser only and the schema tests skip"; fi

install: $(STAMP) $(FRONTEND)/dist/index.html $(CRCL_SCHEMAS)

proto: install
	$(PY) -c 'import setup; setup.generate_stubs()'

run: install
	@$(PY) -m landscape.cell $(if $(CONFIG),--config $(CONFIG))

certs: install
	@$(PY) -m landscape.cell certs $(foreach host,$(HOSTS),--host $(host))
	@$(PY) -m landscape.cell tokens

# Every download is an install step (install, tools, clients), never a test's: the tests use
# what these build and skip, naming the make command, where it is not built.
test: install tools clients
	@$(PY) -m pytest

test-fast: install
	@$(PY) -m pytest -m "not slow"

lint: install
	$(VENV)/bin/buf lint

bench: install
	@$(PY) bench/report.py $(if $(QUICK),--quick)

# Needs Go; without it grpcurl is not built and its tests skip, saying so.
$(GRPCURL):
	@if command -v go >/dev/null; then \
	  GOBIN=$(CURDIR)/.tools/bin go install github.com/fullstorydev/grpcurl/cmd/grpcurl@$(GRPCURL_VERSION); \
	else echo "make tools: no Go on this machine, so no grpcurl (its tests will skip)"; fi

# NIST's reference CRCL client (crcl4java-ui) and its dependencies, from Maven Central as the
# POM says; the gateway's test runs it from this classpath. Needs Java and Maven.
CRCL4JAVA := .tools/crcl4java/classpath.txt
$(CRCL4JAVA): tests/gateway/nist_client.pom.xml
	@if command -v mvn >/dev/null && command -v java >/dev/null; then \
	  mkdir -p $(@D) && cp $< $(@D)/pom.xml && \
	  cd $(@D) && mvn -q -B dependency:build-classpath -Dmdep.outputFile=classpath.txt; \
	else echo "make tools: no Java and Maven here, so no NIST CRCL client (its test will skip)"; fi

tools: $(GRPCURL) $(CRCL4JAVA) $(CRCL_SCHEMAS)

# The Go and TypeScript clients (clients/README.md); stubs and builds stay out of git. Each
# is skipped, saying so, on a machine without its language.
GO_CLIENT := clients/go/bin/landscape-go-client
TS_CLIENT := clients/ts/dist/main.js
clients: clients-go clients-ts
clients-go: $(GO_CLIENT)
clients-ts: $(TS_CLIENT)

$(GO_CLIENT): clients/go/build.sh clients/go/main.go clients/go/go.mod clients/go/go.sum \
		$(wildcard proto/landscape/v1/*.proto) | $(STAMP)
	@if command -v go >/dev/null; then PYTHON=$(CURDIR)/$(PY) clients/go/build.sh; \
	else echo "make clients: no Go here, so no Go client (its test will skip)"; fi

$(TS_CLIENT): clients/ts/package.json clients/ts/package-lock.json clients/ts/tsconfig.json \
		$(wildcard clients/ts/src/*)
	@if command -v npm >/dev/null; then \
	  cd clients/ts && npm ci --no-audit --no-fund --loglevel=error && npx tsc -p .; \
	else echo "make clients: no npm here, so no TypeScript client (its test will skip)"; fi

clean:
	rm -rf $(VENV) .tools gen build *.egg-info .pytest_cache
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
