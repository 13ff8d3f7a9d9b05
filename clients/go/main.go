// Command landscape-go-client drives a LandScape device server from Go: it opens a session,
// locks, activates, runs one MoveAbsolute, waits for the move's done event on the event
// stream, then deactivates and releases. Stubs come from proto/ at build time (build.sh).
package main

import (
	"context"
	"flag"
	"fmt"
	"io"
	"log"
	"os"
	"strconv"
	"strings"
	"time"

	"google.golang.org/grpc"
	"google.golang.org/grpc/credentials/insecure"
	"google.golang.org/grpc/metadata"

	pb "landscape/clients/go/gen/landscapev1"
)

// leaseKey is the metadata key that carries the lease on every mutating call.
const leaseKey = "landscape-lease"

func main() {
	target := flag.String("target", "127.0.0.1:50051", "HOST:PORT of the device server")
	joints := flag.String("joints", "0.5,0,1.57,0,1.57,0", "goal joint values, radians")
	timeout := flag.Duration("timeout", 60*time.Second, "time for the whole sequence")
	flag.Parse()
	goal, err := parseValues(*joints)
	if err != nil {
		log.Fatalf("-joints: %v", err)
	}
	ctx, cancel := context.WithTimeout(context.Background(), *timeout)
	defer cancel()
	if err := run(ctx, *target, goal); err != nil {
		fmt.Fprintln(os.Stderr, "error:", err)
		os.Exit(1)
	}
}

func run(ctx context.Context, target string, goal []float64) error {
	conn, err := grpc.NewClient(target, grpc.WithTransportCredentials(insecure.NewCredentials()))
	if err != nil {
		return err
	}
	defer conn.Close()
	device := pb.NewDeviceServiceClient(conn)

	// The session: Hello, then keep-alives at the interval the device asks for. Ending the
	// stream (cancel) ends the session; the device then releases the lock if we still hold it.
	sessionCtx, endSession := context.WithCancel(ctx)
	defer endSession()
	session, err := pb.NewSessionServiceClient(conn).Connect(sessionCtx)
	if err != nil {
		return err
	}
	hello := &pb.ConnectRequest{Message: &pb.ConnectRequest_Hello{Hello: &pb.Hello{ClientName: "go-client"}}}
	if err := session.Send(hello); err != nil {
		return err
	}
	first, err := session.Recv()
	if err != nil {
		return fmt.Errorf("session: %w", err)
	}
	opened := first.GetOpened()
	fmt.Println("session", opened.GetSessionId())
	go keepAlive(sessionCtx, session, time.Duration(opened.GetKeepaliveIntervalMs())*time.Millisecond)

	locked, err := device.Lock(ctx, &pb.LockRequest{SessionId: opened.GetSessionId(),
		SessionSecret: opened.GetSessionSecret()})
	if err != nil {
		return fmt.Errorf("lock: %w", err)
	}
	fmt.Println("locked:", locked.GetRetVal().GetRetMsg())
	leased := metadata.AppendToOutgoingContext(ctx, leaseKey, locked.GetLease())

	// Subscribe from the first kept event before moving, so the move's events cannot be missed.
	events, err := pb.NewEventServiceClient(conn).Subscribe(ctx, &pb.SubscribeRequest{AfterSequence: new(uint64)})
	if err != nil {
		return err
	}
	if _, err := device.Activate(leased, &pb.ActivateRequest{}); err != nil {
		return fmt.Errorf("activate: %w", err)
	}
	fmt.Println("activated")
	move, err := device.MoveAbsolute(leased, &pb.MoveAbsoluteRequest{PointName: "go-goal",
		Frame: pb.ReferenceFrame_REFERENCE_FRAME_JOINT_FRAME, Values: goal})
	if err != nil {
		return fmt.Errorf("move: %w", err)
	}
	commandID := move.GetRetVal().GetCommandId()
	fmt.Println("started", commandID)
	if err := waitDone(events, commandID); err != nil {
		return err
	}
	fmt.Println("done", commandID)

	position, err := device.GetRobotPosition(ctx, &pb.GetRobotPositionRequest{})
	if err != nil {
		return err
	}
	fmt.Println("joints", position.GetJointPosition())
	if _, err := device.Deactivate(leased, &pb.DeactivateRequest{}); err != nil {
		return fmt.Errorf("deactivate: %w", err)
	}
	if _, err := device.Release(leased, &pb.ReleaseRequest{}); err != nil {
		return fmt.Errorf("release: %w", err)
	}
	fmt.Println("released")
	return nil
}

func keepAlive(ctx context.Context, session pb.SessionService_ConnectClient, every time.Duration) {
	ticker := time.NewTicker(every)
	defer ticker.Stop()
	for counter := uint64(1); ; counter++ {
		select {
		case <-ctx.Done():
			return
		case <-ticker.C:
			msg := &pb.ConnectRequest{Message: &pb.ConnectRequest_KeepAlive{KeepAlive: &pb.KeepAlive{Counter: counter}}}
			if session.Send(msg) != nil {
				return
			}
		}
	}
}

// waitDone reads the event stream until the command's done event (nil) or its failure.
func waitDone(events pb.EventService_SubscribeClient, commandID string) error {
	for {
		reply, err := events.Recv()
		if err == io.EOF {
			return fmt.Errorf("the event stream ended before %s finished", commandID)
		}
		if err != nil {
			return err
		}
		command := reply.GetEvent().GetCommand()
		if command.GetCommandId() != commandID {
			continue
		}
		switch command.GetPhase() {
		case pb.CommandEvent_PHASE_DONE:
			return nil
		case pb.CommandEvent_PHASE_FAILED, pb.CommandEvent_PHASE_ABORTED:
			return fmt.Errorf("%s ended %s: %s", commandID, command.GetPhase(), command.GetMessage())
		}
	}
}

func parseValues(text string) ([]float64, error) {
	var values []float64
	for _, field := range strings.Split(text, ",") {
		value, err := strconv.ParseFloat(strings.TrimSpace(field), 64)
		if err != nil {
			return nil, err
		}
		values = append(values, value)
	}
	return values, nil
}
