// A LandScape device server from TypeScript: open a session, lock, activate, run one
// MoveAbsolute, wait for its done event on the event stream, deactivate and release.
// The contract is read from proto/ at run time with @grpc/proto-loader (no generated code).
import * as path from "path";
import * as grpc from "@grpc/grpc-js";
import * as protoLoader from "@grpc/proto-loader";

const LEASE_KEY = "landscape-lease";   // metadata key of the lease on every mutating call
const PROTO_ROOT = path.resolve(__dirname, "..", "..", "..", "proto");

type Reply = Record<string, any>;
type Unary = (request: object, metadata: grpc.Metadata, callback: (e: grpc.ServiceError | null, r: Reply) => void) => void;

function loadContract(): any {
  const files = ["device_service", "event_service", "session_service"]
    .map((name) => `landscape/v1/${name}.proto`);
  const definition = protoLoader.loadSync(files, {
    includeDirs: [PROTO_ROOT], keepCase: true, longs: String, enums: String, defaults: true,
    oneofs: true,
  });
  return (grpc.loadPackageDefinition(definition) as any).landscape.v1;
}

// One unary call as a promise; `lease` adds the landscape-lease header.
function call(client: any, rpc: string, request: object, lease?: string): Promise<Reply> {
  const metadata = new grpc.Metadata();
  if (lease) metadata.set(LEASE_KEY, lease);
  return new Promise((resolve, reject) => {
    (client[rpc] as Unary).call(client, request, metadata, (error, reply) =>
      error ? reject(new Error(`${rpc}: ${error.details} (${grpc.status[error.code]})`)) : resolve(reply));
  });
}

interface Session { id: string; secret: string; end: () => void }

// The session stream: Hello, then keep-alives at the interval the device asks for.
function openSession(v1: any, target: string, credentials: grpc.ChannelCredentials): Promise<Session> {
  const sessions = new v1.SessionService(target, credentials);
  const stream = sessions.Connect();
  stream.write({ hello: { client_name: "ts-client" } });
  return new Promise((resolve, reject) => {
    stream.once("error", reject);
    stream.once("data", (message: Reply) => {
      const opened = message.opened;
      let counter = 0;
      const timer = setInterval(() => stream.write({ keep_alive: { counter: ++counter } }),
                                opened.keepalive_interval_ms);
      stream.on("error", () => clearInterval(timer));   // cancelled on end, or the device went away
      resolve({
        id: opened.session_id, secret: opened.session_secret,
        end: () => { clearInterval(timer); stream.cancel(); sessions.close(); },
      });
    });
  });
}

// Resolves with the done event of `commandId`, rejects if it fails or is aborted.
function waitDone(events: grpc.ClientReadableStream<Reply>, commandId: string): Promise<Reply> {
  return new Promise((resolve, reject) => {
    events.on("data", (reply: Reply) => {
      const command = reply.event.command;
      if (!command || command.command_id !== commandId) return;
      if (command.phase === "PHASE_DONE") resolve(reply.event);
      if (command.phase === "PHASE_FAILED" || command.phase === "PHASE_ABORTED") {
        reject(new Error(`${commandId} ended ${command.phase}: ${command.message}`));
      }
    });
    events.on("error", (error: grpc.ServiceError) => {
      if (error.code !== grpc.status.CANCELLED) reject(error);
    });
  });
}

async function main(): Promise<void> {
  const args = process.argv.slice(2);
  const target = args[0] ?? "127.0.0.1:50051";
  const goal = (args[1] ?? "0.5,0,1.57,0,1.57,0").split(",").map(Number);
  const v1 = loadContract();
  const credentials = grpc.credentials.createInsecure();
  const device = new v1.DeviceService(target, credentials);
  const eventService = new v1.EventService(target, credentials);

  const session = await openSession(v1, target, credentials);
  console.log("session", session.id);
  // From the first kept event, so the move's events cannot be missed.
  const events = eventService.Subscribe({ after_sequence: 0 });
  try {
    const locked = await call(device, "Lock", { session_id: session.id, session_secret: session.secret });
    const lease: string = locked.lease;
    console.log("locked:", locked.ret_val.ret_msg);
    await call(device, "Activate", {}, lease);
    console.log("activated");
    const move = await call(device, "MoveAbsolute", {
      point_name: "ts-goal", frame: "REFERENCE_FRAME_JOINT_FRAME", values: goal }, lease);
    const commandId: string = move.ret_val.command_id;
    console.log("started", commandId);
    await waitDone(events, commandId);
    console.log("done", commandId);
    const position = await call(device, "GetRobotPosition", {});
    console.log("joints", position.joint_position.join(" "));
    await call(device, "Deactivate", {}, lease);
    await call(device, "Release", {}, lease);
    console.log("released");
  } finally {
    events.cancel();
    session.end();
    device.close();
    eventService.close();
  }
}

const deadline = setTimeout(() => { console.error("error: timed out"); process.exit(1); }, 60_000);
main().then(() => clearTimeout(deadline), (error: Error) => {
  console.error("error:", error.message);
  process.exit(1);
});
