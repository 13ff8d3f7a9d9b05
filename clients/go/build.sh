#!/usr/bin/env bash
# Builds the Go client into clients/go/bin: protoc-gen-go and protoc-gen-go-grpc from the Go
# module proxy (versions pinned below and in go.mod), stubs generated from proto/ with the
# protoc of grpcio-tools (PYTHON, the project's virtualenv), never committed.
set -euo pipefail
cd "$(dirname "$0")"
ROOT=$(cd ../.. && pwd)
PYTHON=${PYTHON:-$ROOT/.venv/bin/python}
PROTOC_GEN_GO=google.golang.org/protobuf/cmd/protoc-gen-go@v1.36.10
PROTOC_GEN_GO_GRPC=google.golang.org/grpc/cmd/protoc-gen-go-grpc@v1.5.1
PACKAGE=landscape/clients/go/gen/landscapev1

GOBIN=$PWD/bin go install "$PROTOC_GEN_GO"
GOBIN=$PWD/bin go install "$PROTOC_GEN_GO_GRPC"

# The .proto files name no go_package: map each to the one Go package here.
protos=$(cd "$ROOT/proto" && ls landscape/v1/*.proto)
mappings=""
for proto in $protos; do mappings="$mappings,M$proto=$PACKAGE"; done
well_known=$("$PYTHON" -c 'import grpc_tools, os; print(os.path.join(os.path.dirname(grpc_tools.__file__), "_proto"))')
rm -rf gen && mkdir -p gen
"$PYTHON" -m grpc_tools.protoc -I"$ROOT/proto" -I"$well_known" \
  --plugin=protoc-gen-go=bin/protoc-gen-go --plugin=protoc-gen-go-grpc=bin/protoc-gen-go-grpc \
  --go_out=gen --go_opt=module=landscape/clients/go/gen${mappings} \
  --go-grpc_out=gen --go-grpc_opt=module=landscape/clients/go/gen${mappings} \
  $protos
go build -o bin/landscape-go-client .
